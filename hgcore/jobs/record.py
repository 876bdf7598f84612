"""The typed job record: a job's Redis hash (``keys.job_key``) and its steps' bookkeeping
(``keys.steps_key``), each field declared once with its type, as RQ's ``Job`` owns its hash through
``to_dict``/``restore``.

Redis keeps text. A field's Python type decides its text form once, for reading and writing alike:
``str`` as is; ``int`` in decimal; ``float`` as ``repr`` (exact round trip); an enum by its value;
``dict`` as JSON; ``X | None`` as ``X``'s form or the empty string. ``to_hash`` writes every field,
``from_hash`` reads them back, and ``encode_fields`` writes some (a transition's, a step's progress),
refusing a name the record does not declare.

A job has ``chunk_count`` chunk steps, named by their index, and one merge step (``MERGE_STEP``); a job of
one chunk renders and merges in one work horse, and still books both. Step ``s``'s field ``f`` is the
steps hash's field ``<s>.<f>``.
"""

from __future__ import annotations

import dataclasses
import json
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Final, Literal, Self

from hgcore.jobs.status import TERMINAL_STATUSES, JobStatus, Priority, StepStatus
from hgcore.noise_target import NoiseTarget

MERGE_STEP: Final = "merge"
"""The name of a job's final step (the merge) in its steps hash; chunk steps are named by their index."""
StepName = int | Literal["merge"]
"""A chunk's index, or ``MERGE_STEP``."""

Decode = Callable[[str], Any]
Encode = Callable[[Any], str]


def decode_hash(mapping: Mapping[bytes, bytes]) -> dict[str, str]:
    """A Redis hash reply as ``str`` keys and values."""
    return {k.decode(): v.decode() for k, v in mapping.items()}


def _codec(hint: Any) -> tuple[Decode, Encode]:
    """How a field of type ``hint`` is read from and written to Redis text."""
    arguments = typing.get_args(hint)
    if typing.get_origin(hint) in (typing.Union, types.UnionType) and type(None) in arguments:
        (inner,) = (a for a in arguments if a is not type(None))
        decode, encode = _codec(inner)
        return (lambda text: decode(text) if text != "" else None), (lambda v: "" if v is None else encode(v))
    if hint is str or typing.get_origin(hint) is Literal:
        return str, str
    if hint is int:
        return int, str
    if hint is float:
        return float, lambda v: repr(float(v))
    if isinstance(hint, type) and issubclass(hint, Enum):
        return hint, lambda v: hint(v).value
    if hint is dict or typing.get_origin(hint) is dict:
        return json.loads, json.dumps
    raise TypeError(f"no Redis text form for {hint!r}")


class HashRecord:
    """A dataclass stored as a Redis hash: one codec per field, from its type (module docstring). A field
    whose hash name differs from its Python name says so in ``metadata={"hash": name}``."""

    __slots__ = ()

    _codecs: typing.ClassVar[dict[str, tuple[str, Decode, Encode]]]
    """Python name → (hash name, decode, encode), built once per class."""
    _decoders: typing.ClassVar[dict[str, tuple[str, Decode]]]
    """Hash name → (Python name, decode): ``from_hash``'s table (the API reads records on every GET)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls._codecs, cls._decoders = {}, {}

    @classmethod
    def _field_codecs(cls) -> dict[str, tuple[str, Decode, Encode]]:
        if not cls._codecs:
            hints = typing.get_type_hints(cls)
            for f in dataclasses.fields(cls):  # type: ignore[arg-type]
                cls._codecs[f.name] = (f.metadata.get("hash", f.name), *_codec(hints[f.name]))
            cls._decoders |= {
                hash_name: (name, decode) for name, (hash_name, decode, _) in cls._codecs.items()
            }
        return cls._codecs

    @classmethod
    def hash_name(cls, name: str) -> str:
        """The hash field of the Python field ``name`` (KeyError: the record declares no such field)."""
        return cls._field_codecs()[name][0]

    @classmethod
    def encode_fields(cls, **values: Any) -> dict[str, str]:
        """Some fields in their hash form, for a partial update (KeyError names an undeclared field)."""
        codecs = cls._field_codecs()
        encoded = {}
        for name, value in values.items():
            if name not in codecs:
                raise KeyError(f"{cls.__name__} has no field {name!r}")
            hash_name, _, encode = codecs[name]
            encoded[hash_name] = encode(value)
        return encoded

    def to_hash(self) -> dict[str, str]:
        """Every field in its hash form."""
        codecs = self._field_codecs().items()
        return {hash_name: encode(getattr(self, name)) for name, (hash_name, _, encode) in codecs}

    @classmethod
    def from_hash(cls, fields: Mapping[str, str]) -> Self:
        """The record from its hash fields (a field absent from the hash keeps its default; one the record
        does not declare is ignored)."""
        if not cls._decoders:
            cls._field_codecs()
        decoders = cls._decoders
        return cls(**{decoders[k][0]: decoders[k][1](text) for k, text in fields.items() if k in decoders})


@dataclass(frozen=True, slots=True)
class JobRecord(HashRecord):
    """A job's hash: who asked for what, its status and its timestamps (Unix seconds)."""

    id: str
    owner: str
    status: JobStatus
    priority: Priority
    spp: int
    seed: int
    chunk_count: int = field(metadata={"hash": "chunks"})
    created_at: float
    name: str | None = None
    width: int | None = None
    """The film's width (px)."""
    height: int | None = None
    target_rel_error: float | None = None
    time_budget_s: float | None = None
    target_quantile: float | None = None
    started_at: float | None = None
    finished_at: float | None = None
    error: str | None = None
    noise_target_outcome: dict[str, Any] | None = field(default=None, metadata={"hash": "noise_target"})
    """A noise-target job's rounds so far, then what it achieved (``hgcore.noise_target.summary_block``)."""
    progress_published: float | None = None
    """The largest progress published on the job's channel (it never goes backwards)."""

    @property
    def noise_target(self) -> NoiseTarget | None:
        """The requested noise target, or None for a fixed-spp job."""
        return NoiseTarget.from_options(self.target_rel_error, self.time_budget_s, self.target_quantile)

    @property
    def is_final(self) -> bool:
        """Whether the job reached a final status (nothing is left to do for it)."""
        return self.status in TERMINAL_STATUSES


@dataclass(frozen=True, slots=True)
class StepRecord(HashRecord):
    """One step's bookkeeping (a chunk's, or the merge's), written by the work horses that run it."""

    status: StepStatus = "queued"
    progress: float = 0.0
    worker: str | None = None
    pid: int | None = None
    spp: int | None = None
    started_at: float | None = None
    finished_at: float | None = None
    attempts: int = 0
    """Work horses that started the step (one more per retry or hand-back)."""
    completions: int = 0
    """Times the step ran to completion (1 for a step that is done, whatever retries it took)."""
    samples: int | None = None
    seconds: float | None = None

    @staticmethod
    def field_name(step: StepName, name: str) -> str:
        """The steps hash's field of step ``step``'s field ``name``."""
        return f"{step}.{StepRecord.hash_name(name)}"

    @classmethod
    def encode_step(cls, step: StepName, **values: Any) -> dict[str, str]:
        """Some fields of step ``step`` in their steps-hash form."""
        return {f"{step}.{name}": text for name, text in cls.encode_fields(**values).items()}


@dataclass(frozen=True, slots=True)
class JobSteps:
    """Every step of a job: its chunks, in index order, and its merge (None until the merge started or
    the job was canceled)."""

    chunks: list[StepRecord]
    merge: StepRecord | None

    @classmethod
    def from_hash(cls, fields: Mapping[str, str], chunk_count: int) -> JobSteps:
        """The steps of a job of ``chunk_count`` chunks from its steps hash."""
        by_step: dict[str, dict[str, str]] = {}
        for key, value in fields.items():
            step, _, name = key.partition(".")
            by_step.setdefault(step, {})[name] = value
        chunks = [StepRecord.from_hash(by_step.get(str(i), {})) for i in range(chunk_count)]
        merge = StepRecord.from_hash(by_step[MERGE_STEP]) if MERGE_STEP in by_step else None
        return cls(chunks, merge)

    def completions(self) -> dict[str, int]:
        """How many times each step that completed did so (``"<index>"`` or ``"merge"`` → count)."""
        named = [(str(i), step) for i, step in enumerate(self.chunks)]
        named += [(MERGE_STEP, self.merge)] if self.merge is not None else []
        return {name: step.completions for name, step in named if step.completions}

    @staticmethod
    def initial_hash(chunk_count: int) -> dict[str, str]:
        """A new job's steps hash: every chunk queued."""
        queued: dict[str, str] = {}
        for index in range(chunk_count):
            queued |= StepRecord.encode_step(index, status="queued")
        return queued
