"""``/v1/tokens`` (admin): create, list and revoke API tokens."""

from __future__ import annotations

from fastapi import APIRouter, Response, status
from fastapi.responses import JSONResponse

from service.api.deps import Admin, TokensDep
from service.models import Problem, TokenCreate, TokenCreated, TokenView

router = APIRouter(prefix="/v1/tokens", tags=["tokens"])
_ERRORS = {401: {"model": Problem}, 403: {"model": Problem}}


@router.post("", status_code=status.HTTP_201_CREATED, response_model=TokenCreated, responses=_ERRORS)
def create_token(body: TokenCreate, tokens: TokensDep, _: Admin) -> TokenCreated:
    """The secret is in the response only; the server keeps its SHA-256."""
    secret, info = tokens.create(body.owner, tuple(body.scopes), body.name)
    return TokenCreated(token=secret, **info.__dict__)


@router.get("", response_model=list[TokenView], responses=_ERRORS)
def list_tokens(tokens: TokensDep, _: Admin) -> list[TokenView]:
    return [TokenView(**{**info.__dict__, "scopes": list(info.scopes)}) for info in tokens.list()]


@router.delete(
    "/{token_id}", status_code=status.HTTP_204_NO_CONTENT, responses={**_ERRORS, 404: {"model": Problem}}
)
def revoke_token(token_id: str, tokens: TokensDep, _: Admin) -> Response:
    if not tokens.revoke(token_id):
        return JSONResponse({"detail": f"token_id: no token {token_id!r}"}, status.HTTP_404_NOT_FOUND)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
