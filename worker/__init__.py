"""Render workers: optics core (``worker.optics``), Mitsuba integrator (``worker.render``), queue tasks."""
