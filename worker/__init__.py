"""Render workers: the Mitsuba integrator (``worker.render``), the RQ worker class and its queue tasks."""
