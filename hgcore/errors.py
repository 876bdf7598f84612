"""The one error type for bad input, apart from programming errors.

``InputError`` is what validation raises for anything a request, a scene, a command-line flag, an
uploaded file or the deployment's configuration carries; its message starts with the offending field or
parameter (``x: must be in [0, 15], got 16``). The API answers it with a 422 naming the field and the CLI
with one line and exit 2. Every other exception is a bug: the API answers 500 and logs the traceback, the
CLI prints the traceback and exits 1. It subclasses ``ValueError`` so that pydantic validators report it
as a validation failure and code that checks ``ValueError`` keeps working.
"""

from __future__ import annotations


class InputError(ValueError):
    """Input that cannot be accepted; ``str(error)`` names the field first (``field: what is wrong``)."""
