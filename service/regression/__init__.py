"""Scheduled regression suites (issue 7): schedules, runs, baselines, metrics, history, webhooks."""
