"""The job domain shared by the API and the workers, one concept a module:

* ``status``      — job and step statuses and the state machine's allowed transitions.
* ``keys``        — every Redis key and pub/sub channel of a job (store keys: ``hgcore.artifacts.keys``).
* ``record``      — ``JobRecord``, ``StepRecord``: the typed job hash and steps hash.
* ``views``       — the job's view (API responses and ``manifest.json``) built from its record and steps.
* ``manifest``    — ``worker.log``, artifact digests and ``manifest.json`` of a job that ended.
* ``lifecycle``   — ``JobLifecycle``: the one owner of a job's keys; every change a job goes through.
* ``queue_graph`` — the RQ job graph of a job: task names, RQ ids, queues, and how it is enqueued.
* ``reconcile``   — ``QueueReconciler``: re-enqueues the RQ steps of unfinished jobs that nothing will run.
"""
