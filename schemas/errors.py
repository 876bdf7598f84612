"""Scene errors that say where: a JSON pointer (RFC 6901) into the scene, or a USD prim path."""

from __future__ import annotations

import re
from typing import Any, TypedDict

from hgcore.errors import InputError

# USD's errors ("Error in 'pxrInternal_v0_26::Sdf_CrateFile::_ReadBootStrap' at line 3542 in file
# /opt/USD/pxr/usd/sdf/crateFile.cpp : 'Sdf crate bootstrap section corrupt'") name the library's build
# tree, and layer errors name the server's temporary upload folder.
_TF_ERROR_PREFIX = re.compile(r"Error in '[^']*' at line \d+ in file \S+ : ")
# An absolute path to a file (its last segment has an extension, which USD prim paths such as /World/Box
# and JSON pointers never have).
_ABSOLUTE_PATH = re.compile(r"(?<![\w.~])/(?:[^\s'\"@<>:,;()\[\]/]+/)+([^\s'\"@<>:,;()\[\]/.]*\.\w+)")


class SceneProblem(TypedDict):
    """One problem: ``pointer`` is a JSON pointer (``/shapes/2/radius_m``) or a USD prim path."""

    pointer: str
    message: str


class SceneError(InputError):
    """A scene (JSON or USD) that cannot be accepted; ``problems`` lists every located problem.

    ``str(error)`` starts with the first offending location, e.g. ``/shapes/2/radius_m: Input should be
    greater than 0``, followed by the others on their own lines.
    """

    def __init__(self, problems: list[SceneProblem]) -> None:
        if not problems:
            raise ValueError("problems must list at least one problem")
        self.problems: list[SceneProblem] = list(problems)
        super().__init__("\n".join(f"{p['pointer'] or '/'}: {p['message']}" for p in self.problems))

    @classmethod
    def at(cls, pointer: str, message: str) -> SceneError:
        """A SceneError with a single problem."""
        return cls([{"pointer": pointer, "message": message}])

    def to_json(self) -> dict[str, Any]:
        """The error as a JSON body: ``{"detail": [{"pointer", "message"}, ...]}``."""
        return {"detail": [dict(p) for p in self.problems]}


def json_pointer(parts: list[str | int]) -> str:
    """Join path parts into a JSON pointer, escaping ``~`` and ``/`` as RFC 6901 requires."""
    return "".join("/" + str(part).replace("~", "~0").replace("/", "~1") for part in parts)


def without_paths(message: str) -> str:
    """``message`` (from a parser such as USD's) with the source locations of its errors removed and every
    absolute file path cut to its base name: an error names the user's file, never the server's folders
    or the library's build tree."""
    return _ABSOLUTE_PATH.sub(r"\1", _TF_ERROR_PREFIX.sub("", message))
