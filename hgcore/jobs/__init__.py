"""The job domain shared by the API and the workers, one concept a module:

* ``status``      — job statuses and the state machine's allowed transitions.
* ``keys``        — every Redis key and pub/sub channel of a job (store keys: ``hgcore.artifacts.keys``).
* ``views``       — the job's view (API responses and ``manifest.json``) built from its record.
* ``queue_graph`` — the RQ job graph of a job: task names, RQ ids, queues, and how it is enqueued.
* ``records``     — ``JobRecords``: the record in Redis, atomic transitions, events, and the chunk
                    bookkeeping that workers write.
* ``reconcile``   — ``QueueReconciler``: re-enqueues the RQ steps of unfinished jobs that nothing will run.
"""
