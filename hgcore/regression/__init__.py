"""The regression domain, shared by the API (schedules, starting runs) and the workers (evaluating runs):
suites, schedules, runs and baselines (``models``), their persistence (``store``), the noise-aware
comparison of a render with its baseline (``metrics`` over ``images``), failure webhooks (``webhooks``)
and the evaluation of a finished run (``evaluation``)."""
