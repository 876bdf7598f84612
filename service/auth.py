"""Bearer-token authentication, scopes, owner visibility and per-token rate limits (all state in Redis).

A token is ``hgr_`` + 32 random bytes (URL-safe base64); Redis stores only its SHA-256 hex digest, so a
leaked database reveals no usable token. Scopes: ``submit`` (create/cancel/delete own jobs), ``read``
(see own jobs and artifacts), ``admin`` (everything, every owner, token management). The rate limit is a
fixed one-minute window per token (``service.rate_limit``: counted per process, added to a shared Redis
counter in batches).
"""

from __future__ import annotations

import hashlib
import os
import secrets
import time
from dataclasses import dataclass
from pathlib import Path

import redis
import redis.asyncio as aioredis

from hgcore.errors import InputError
from service.rate_limit import RequestCounter, counter_key, current_window, retry_after_s

SCOPES: tuple[str, ...] = ("submit", "read", "admin")
TOKEN_PREFIX = "hgr_"
_TOKEN_KEY = "hgrender:token:{}"
_TOKEN_INDEX = "hgrender:tokens"


class AuthenticationError(Exception):
    """Missing, malformed or unknown token (HTTP 401)."""


class PermissionDeniedError(Exception):
    """The token lacks the scope the operation needs (HTTP 403)."""


class RateLimitedError(Exception):
    """The token exceeded its requests per minute (HTTP 429); ``retry_after_s`` says when to retry."""

    def __init__(self, retry_after_s: int) -> None:
        super().__init__(f"rate limit exceeded; retry after {retry_after_s} s")
        self.retry_after_s = retry_after_s


@dataclass(frozen=True)
class Principal:
    """Who is calling: the owner name jobs are filed under, and the token's scopes."""

    owner: str
    scopes: frozenset[str]
    token_id: str | None = None

    @property
    def is_admin(self) -> bool:
        return "admin" in self.scopes

    def has_scope(self, scope: str) -> bool:
        # admin implies every scope
        return self.is_admin or scope in self.scopes

    def require(self, scope: str) -> None:
        if not self.has_scope(scope):
            raise PermissionDeniedError(f"scope: this token lacks the {scope!r} scope")

    def can_see(self, owner: str) -> bool:
        return self.is_admin or owner == self.owner


LOCAL_DEVELOPER = Principal(owner="local", scopes=frozenset(SCOPES), token_id=None)
"""The principal of every request when ``HGRENDER_AUTH=off``."""


@dataclass(frozen=True)
class TokenInfo:
    """A stored token (without the secret): ``id`` is the first 12 hex digits of its hash."""

    id: str
    owner: str
    scopes: tuple[str, ...]
    name: str
    created_at: float


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


def validate_scopes(scopes: list[str] | tuple[str, ...]) -> tuple[str, ...]:
    unknown = sorted(set(scopes) - set(SCOPES))
    if unknown or not scopes:
        raise InputError(f"scopes: must be a non-empty subset of {list(SCOPES)}; unknown: {unknown}")
    return tuple(s for s in SCOPES if s in scopes)


class TokenRegistry:
    """Create, look up, list and revoke tokens in Redis."""

    def __init__(self, client: redis.Redis) -> None:
        self.client = client

    def register(self, token: str, owner: str, scopes: tuple[str, ...], name: str = "") -> TokenInfo:
        """Store the hash of an existing secret ``token`` (used for the admin token file)."""
        if not owner or len(owner) > 128:
            raise InputError("owner: must be 1 to 128 characters")
        token_hash = hash_token(token)
        info = TokenInfo(token_hash[:12], owner, validate_scopes(scopes), name, time.time())
        mapping = {
            "id": info.id,
            "owner": owner,
            "scopes": ",".join(info.scopes),
            "name": name,
            "created_at": repr(info.created_at),
        }
        with self.client.pipeline() as pipe:
            pipe.hset(_TOKEN_KEY.format(token_hash), mapping=mapping)
            pipe.sadd(_TOKEN_INDEX, token_hash)
            pipe.execute()
        return info

    def create(self, owner: str, scopes: tuple[str, ...], name: str = "") -> tuple[str, TokenInfo]:
        """A new random token; returns (secret, info). The secret is shown once and never stored."""
        token = TOKEN_PREFIX + secrets.token_urlsafe(32)
        return token, self.register(token, owner, scopes, name)

    def list(self) -> list[TokenInfo]:
        hashes = sorted(h.decode() for h in self.client.smembers(_TOKEN_INDEX))
        with self.client.pipeline() as pipe:
            for token_hash in hashes:
                pipe.hgetall(_TOKEN_KEY.format(token_hash))
            records = pipe.execute()
        return [
            TokenInfo(
                r[b"id"].decode(),
                r[b"owner"].decode(),
                tuple(r[b"scopes"].decode().split(",")),
                r[b"name"].decode(),
                float(r[b"created_at"]),
            )
            for r in records
            if r
        ]

    def revoke(self, token_id: str) -> bool:
        """Delete the token whose id is ``token_id``; False if there is none."""
        for token_hash in (h.decode() for h in self.client.smembers(_TOKEN_INDEX)):
            if token_hash.startswith(token_id) and len(token_id) == 12:
                with self.client.pipeline() as pipe:
                    pipe.delete(_TOKEN_KEY.format(token_hash))
                    pipe.srem(_TOKEN_INDEX, token_hash)
                    pipe.execute()
                return True
        return False


# KEYS: token hash, this minute's rate counter. Returns false for an unknown token, else
# {counter value, hgetall...}: one read-only round trip authenticates and reads the shared count.
_AUTHENTICATE_LUA = """
local record = redis.call('HGETALL', KEYS[1])
if #record == 0 then return false end
return {tonumber(redis.call('GET', KEYS[2]) or '0'), record}
"""


class RequestAuthenticator:
    """Authenticates a request's bearer token and applies its rate limit, on the API's asyncio client.

    Requests are counted by ``service.rate_limit.RequestCounter``: read here, written in batches (a write
    per request would wait for the private Redis's fsync).
    """

    def __init__(self, aclient: aioredis.Redis, limit_per_minute: int) -> None:
        self.limit_per_minute = limit_per_minute
        self.counter = RequestCounter(aclient)
        self._script = aclient.register_script(_AUTHENTICATE_LUA)

    async def __call__(self, token: str | None) -> Principal:
        if not token:
            raise AuthenticationError("authorization: missing bearer token")
        if not token.startswith(TOKEN_PREFIX) or len(token) > 256:
            raise AuthenticationError("authorization: malformed bearer token")
        token_hash = hash_token(token)
        now = time.time()
        window = current_window(now)
        rate_key = counter_key(token_hash[:12], window)
        result = await self._script(keys=[_TOKEN_KEY.format(token_hash), rate_key])
        if not result:
            raise AuthenticationError("authorization: unknown or revoked token")
        shared, flat = int(result[0]), result[1]
        record = {flat[i].decode(): flat[i + 1].decode() for i in range(0, len(flat), 2)}
        if self.counter.count(rate_key, shared) > self.limit_per_minute:
            raise RateLimitedError(retry_after_s=retry_after_s(window, now))
        return Principal(
            owner=record["owner"], scopes=frozenset(record["scopes"].split(",")), token_id=record["id"]
        )

    async def aclose(self) -> None:
        await self.counter.aclose()


def ensure_admin_token(client: redis.Redis, token_path: Path) -> str:
    """Make sure an admin token exists in ``token_path`` (mode 0600) and in Redis; return it.

    An existing file is re-registered (Redis may have been replaced); otherwise a new token is created
    and written atomically with owner-only permissions before it is registered.
    """
    token_path = Path(token_path)
    registry = TokenRegistry(client)
    if token_path.exists():
        token = token_path.read_text().strip()
        registry.register(token, owner="admin", scopes=("admin",), name="first admin token")
        return token
    token = TOKEN_PREFIX + secrets.token_urlsafe(32)
    token_path.parent.mkdir(parents=True, exist_ok=True)
    tmp_path = token_path.with_name(f".{token_path.name}.tmp")
    fd = os.open(tmp_path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as out:
        out.write(token + "\n")
    os.replace(tmp_path, token_path)
    registry.register(token, owner="admin", scopes=("admin",), name="first admin token")
    return token
