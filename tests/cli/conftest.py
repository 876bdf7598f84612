"""The CLI tests share the viewer tests' live ``hgrender serve`` (a subprocess with its private Redis,
auth on, one worker): the client commands are exercised as users run them, against the real service."""

from tests.web.conftest import Served, served

__all__ = ["Served", "served"]
