"""What every request meets before a handler: body limit, authentication order, short 422s.

* :class:`BodyLimitMiddleware` (pure ASGI) refuses a body over
  ``max_body_bytes`` with 413 *before* it is parsed: a declared
  ``Content-Length`` is refused without reading, a chunked body as soon as it
  passes the limit. An unauthenticated oversized request gets 401 instead (the
  caller has to learn that first). A JSON body that is not UTF-8 is a 422
  (``json_invalid``), never a 400.
* :func:`validation_error_handler` answers request validation errors: for a
  body that is not JSON at all, an unauthenticated caller gets 401 (FastAPI
  decodes the body before it runs the route's auth dependency; with valid JSON
  the dependency runs first anyway). Every 422 echoes at most
  ``ECHO_CHARS`` characters of any input, so a 50 MB field is not sent back.
* Text PostgreSQL cannot store and numbers JSON does not have are refused at the
  door with a 422 naming where they are, on both databases alike: a NUL character
  (``\\u0000`` in a JSON body, ``%00`` in a path or query) and the ``NaN`` /
  ``Infinity`` tokens Python's JSON reader accepts.
* :class:`AllowHeaderMiddleware` makes a 405's ``Allow`` list every method of the path.
* :func:`document_auth_responses` adds 401 and 403 to every operation that
  declares a security requirement in ``/openapi.json``.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Awaitable, Callable
from typing import Any

from fastapi import FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool
from starlette.types import ASGIApp, Message, Receive, Scope, Send

DEFAULT_MAX_BODY_BYTES = 1_000_000
ECHO_CHARS = 64  # at most this much of an input (or a key name) goes back in a 422
MSG_CHARS = 300
WITH_BODY = frozenset({"POST", "PUT", "PATCH", "DELETE"})

TokenCheck = Callable[[Scope], Awaitable[bool]]


class BodyLimitMiddleware:
    """413 for bodies over the limit (401 first when unauthenticated); 422 for non-UTF-8 JSON."""

    def __init__(self, app: ASGIApp, max_body_bytes: int, authenticated: TokenCheck) -> None:
        self.app = app
        self.max_body_bytes = max_body_bytes
        self.authenticated = authenticated

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        nul = _nul_in_url(scope)
        if nul is not None:
            await self._refuse(scope, send, nul)
            return
        if scope["method"] not in WITH_BODY:
            await self.app(scope, receive, send)
            return
        headers = _headers(scope)
        declared = headers.get("content-length")
        if declared is not None and declared.isdigit() and int(declared) > self.max_body_bytes:
            await self._too_large(scope, send)
            return
        chunks: list[bytes] = []
        size = 0
        more = True
        while more:
            message = await receive()
            if message["type"] == "http.disconnect":
                return
            chunk = message.get("body", b"")
            size += len(chunk)
            if size > self.max_body_bytes:
                await self._too_large(scope, send)
                return
            chunks.append(chunk)
            more = message.get("more_body", False)
        body = b"".join(chunks)
        if body and _is_json(headers.get("content-type", "")):
            try:
                body.decode("utf-8")
            except UnicodeDecodeError as exc:
                await _send_json(send, 422, {"detail": [{
                    "type": "json_invalid", "loc": ["body", exc.start],
                    "msg": f"JSON body is not UTF-8 (byte {exc.start}: {exc.reason})",
                    "input": None}]})
                return
            refused = unstorable_json(body)
            if refused is not None:
                await self._refuse(scope, send, refused)
                return
        await self.app(scope, _replay(body, receive), send)

    async def _refuse(self, scope: Scope, send: Send, error: dict[str, Any]) -> None:
        """422 for input no database row can hold (401 first when unauthenticated)."""
        if not await self.authenticated(scope):
            await _send_json(send, 401, UNAUTHORIZED_BODY, {"www-authenticate": "Bearer"})
            return
        await _send_json(send, 422, {"detail": [error]})

    async def _too_large(self, scope: Scope, send: Send) -> None:
        if not await self.authenticated(scope):
            await _send_json(send, 401, UNAUTHORIZED_BODY, {"www-authenticate": "Bearer"})
            return
        await _send_json(send, 413, {"detail": (
            f"request body over the limit of {self.max_body_bytes} bytes "
            "(SOAKCAL_MAX_BODY_BYTES)")})


# JSON's grammar has no NaN or Infinity; Python's reader accepts them, PostgreSQL's JSON
# columns do not, and a 422 echoing them could not be serialised.
_NON_JSON_CONSTANTS = (b"NaN", b"Infinity")
_NUL_ESCAPE = b"\\u0000"


class _NotJsonNumber(ValueError):
    pass


def _no_constant(token: str) -> Any:
    raise _NotJsonNumber(token)


def unstorable_json(body: bytes) -> dict[str, Any] | None:
    """A 422 ``detail`` entry for a NUL character or a NaN/Infinity in a JSON body, else None.

    A byte scan first, so an ordinary body is not parsed twice; a body that is not
    JSON at all is left to FastAPI's own ``json_invalid``.
    """
    if _NUL_ESCAPE not in body and not any(c in body for c in _NON_JSON_CONSTANTS):
        return None
    try:
        doc = json.loads(body, parse_constant=_no_constant)
    except _NotJsonNumber as exc:
        return {"type": "finite_number", "loc": ["body"],
                "msg": f"{exc} is not a JSON number; give a finite number", "input": str(exc)}
    except ValueError:
        return None
    where = _nul_path(doc, ["body"])
    if where is None:
        return None
    return {"type": "string_nul", "loc": [short(str(p)) if not isinstance(p, int) else p
                                         for p in where],
            "msg": "text contains a NUL character (\\u0000), which cannot be stored; remove it",
            "input": None}


def _nul_path(value: Any, loc: list[str | int]) -> list[str | int] | None:
    """Where the first NUL character of a parsed JSON document is (a key or a string)."""
    if isinstance(value, str):
        return loc if "\x00" in value else None
    if isinstance(value, dict):
        for key, item in value.items():
            found = (loc + [key]) if "\x00" in key else _nul_path(item, loc + [key])
            if found is not None:
                return found
    if isinstance(value, list):
        for i, item in enumerate(value):
            found = _nul_path(item, loc + [i])
            if found is not None:
                return found
    return None


def _nul_in_url(scope: Scope) -> dict[str, Any] | None:
    """A 422 entry for a NUL character (``%00``) in the path or the query string, else None."""
    if "\x00" in scope.get("path", ""):
        return {"type": "string_nul", "loc": ["path"],
                "msg": "the path contains a NUL character (%00); remove it", "input": None}
    query = scope.get("query_string", b"")
    if b"%00" in query or b"\x00" in query:
        from urllib.parse import parse_qsl

        for name, value in parse_qsl(query.decode("latin-1"), keep_blank_values=True):
            if "\x00" in name or "\x00" in value:
                return {"type": "string_nul", "loc": ["query", short(name.replace("\x00", ""))],
                        "msg": "the query contains a NUL character (%00); remove it",
                        "input": None}
    return None


class AllowHeaderMiddleware:
    """A 405's ``Allow`` lists every documented method of the path, not just one route's.

    FastAPI registers one route per method; Starlette answers a wrong method with
    the ``Allow`` of the first route whose path matched (``GET`` for a path that
    also has ``POST``), which contradicts the OpenAPI document. The methods are
    read from that document (``openapi()``), so the two cannot disagree.
    """

    def __init__(self, app: ASGIApp, openapi: Callable[[], dict[str, Any]]) -> None:
        self.app = app
        self.openapi = openapi
        self._paths: list[tuple[re.Pattern[str], list[str]]] | None = None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return

        async def send_with_allow(message: Message) -> None:
            if message["type"] == "http.response.start" and message["status"] == 405:
                allow = self.methods(scope["path"])
                if allow:
                    headers = [(k, v) for k, v in message.get("headers", [])
                               if k.lower() != b"allow"]
                    headers.append((b"allow", ", ".join(allow).encode()))
                    message = {**message, "headers": headers}
            await send(message)

        await self.app(scope, receive, send_with_allow)

    def methods(self, path: str) -> list[str]:
        if self._paths is None:
            self._paths = [
                (re.compile("^" + re.sub(r"\\{[^}]+\\}", "[^/]+", re.escape(template)) + "$"),
                 sorted(m.upper() for m in item if m.upper() in HTTP_METHODS))
                for template, item in self.openapi().get("paths", {}).items()]
        return next((methods for pattern, methods in self._paths if pattern.match(path)), [])


HTTP_METHODS = frozenset({"GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS"})


UNAUTHORIZED_BODY = {"detail": "missing or unknown bearer token (Authorization: Bearer <token>)"}


def _replay(body: bytes, receive: Receive) -> Receive:
    sent = False

    async def replay() -> Message:
        nonlocal sent
        if not sent:
            sent = True
            return {"type": "http.request", "body": body, "more_body": False}
        return await receive()  # after the body: wait for the disconnect as usual

    return replay


def _headers(scope: Scope) -> dict[str, str]:
    return {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}


def _is_json(content_type: str) -> bool:
    media = content_type.split(";", 1)[0].strip().lower()
    return media == "application/json" or media.endswith("+json")


async def _send_json(send: Send, status: int, body: Any,
                     extra_headers: dict[str, str] | None = None) -> None:
    payload = json.dumps(body).encode("utf-8")
    headers = [(b"content-type", b"application/json"),
               (b"content-length", str(len(payload)).encode())]
    headers += [(k.encode(), v.encode()) for k, v in (extra_headers or {}).items()]
    await send({"type": "http.response.start", "status": status, "headers": headers})
    await send({"type": "http.response.body", "body": payload})


def bearer_check(app: FastAPI) -> TokenCheck:
    """Whether a request carries a bearer token the database knows (one indexed lookup)."""

    async def authenticated(scope: Scope) -> bool:
        from http.cookies import SimpleCookie

        from sqlalchemy import select

        from service.api.auth import SESSION_COOKIE, hash_token, token_status
        from service.db.models import ApiToken

        headers = _headers(scope)
        scheme, _, token = headers.get("authorization", "").partition(" ")
        if scheme.lower() != "bearer" or not token.strip():
            # the dashboard signs in with an HttpOnly cookie (service/api/auth.py)
            morsel = SimpleCookie(headers.get("cookie", "")).get(SESSION_COOKIE)
            token = morsel.value if morsel is not None else ""
        if not token.strip():
            return False
        token_hash = hash_token(token.strip())

        def lookup() -> bool:
            with app.state.session_factory() as session:
                row = session.scalar(select(ApiToken).where(ApiToken.token_hash == token_hash))
                # a revoked or expired token is as good as none (same rule as require_role)
                return row is not None and token_status(row) == "active"

        return await run_in_threadpool(lookup)

    return authenticated


def short(value: Any) -> Any:
    """An input as a 422 may echo it: strings cut to ``ECHO_CHARS``, containers summarised."""
    if isinstance(value, str):
        return value if len(value) <= ECHO_CHARS else value[:ECHO_CHARS] + "…"
    if isinstance(value, bytes):
        return short(value.decode("utf-8", "replace"))
    if isinstance(value, dict):
        text = json.dumps(jsonable_encoder(value), ensure_ascii=False)
        return value if len(text) <= ECHO_CHARS else f"<object with {len(value)} key(s)>"
    if isinstance(value, list | tuple):
        text = json.dumps(jsonable_encoder(list(value)), ensure_ascii=False)
        return value if len(text) <= ECHO_CHARS else f"<array of {len(value)} item(s)>"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)  # JSON has no NaN or Infinity: echoed as text
    if isinstance(value, bool | int | float) or value is None:
        return value
    return short(str(value))


def short_errors(errors: Any) -> list[dict[str, Any]]:
    """422 ``detail`` entries with bounded loc, msg and input (and no ``ctx``/``url``)."""
    out: list[dict[str, Any]] = []
    for error in list(errors)[:50]:
        loc = [part if isinstance(part, int) else short(str(part))
               for part in error.get("loc", ())]
        msg = str(error.get("msg", ""))
        if error.get("type") == "extra_forbidden" and loc and loc[0] == "query":
            msg = f"unknown query parameter {loc[-1]!r}; see docs/api.md"
        elif error.get("type") == "extra_forbidden" and loc:
            msg = (f"unknown field {loc[-1]!r}; see the campaign and schedule fields in "
                   "docs/api.md")
        out.append({"type": str(error.get("type", "value_error")), "loc": loc,
                    "msg": short_msg(msg), "input": short(error.get("input"))})
    return out


def short_msg(msg: str) -> str:
    return msg if len(msg) <= MSG_CHARS else msg[:MSG_CHARS] + "…"


async def validation_error_handler(request: Request, exc: Exception) -> JSONResponse:
    """422 with short echoes; 401 when the body was not even JSON and the caller unknown."""
    assert isinstance(exc, RequestValidationError)
    errors = list(exc.errors())
    not_json = any(e.get("type") == "json_invalid" for e in errors)
    if not_json and _route_needs_auth(request) and not await bearer_check(request.app)(
            request.scope):
        return JSONResponse(UNAUTHORIZED_BODY, status_code=401,
                            headers={"WWW-Authenticate": "Bearer"})
    return JSONResponse({"detail": short_errors(errors)}, status_code=422)


def _route_needs_auth(request: Request) -> bool:
    """Whether the matched operation declares a security requirement (all but health)."""
    route = request.scope.get("route")
    path = getattr(route, "path_format", None)
    if path is None:
        return True  # unknown: the safe answer
    operation = request.app.openapi().get("paths", {}).get(path, {}).get(
        request.method.lower(), {})
    return bool(operation.get("security"))


AUTH_RESPONSES: dict[str, dict[str, Any]] = {
    "401": {"description": "missing, unknown or expired bearer token",
            "headers": {"WWW-Authenticate": {"schema": {"type": "string"},
                                             "description": "Bearer"}},
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorOut"}}}},
    "403": {"description": "the token's role is below the one this operation needs",
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorOut"}}}},
}
BODY_RESPONSES: dict[str, dict[str, Any]] = {
    "413": {"description": "request body over SOAKCAL_MAX_BODY_BYTES (default 1 MB)",
            "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ErrorOut"}}}},
}


def document_auth_responses(app: FastAPI) -> None:
    """Wrap ``app.openapi`` so every secured operation lists 401/403 (and 413 with a body)."""
    build = app.openapi

    def openapi() -> dict[str, Any]:
        if app.openapi_schema is not None:
            return app.openapi_schema
        schema = build()
        schemas = schema.setdefault("components", {}).setdefault("schemas", {})
        schemas.setdefault("ErrorOut", {
            "title": "ErrorOut", "type": "object", "required": ["detail"],
            "properties": {"detail": {"title": "Detail"}}})
        for path_item in schema.get("paths", {}).values():
            for method, operation in path_item.items():
                if not isinstance(operation, dict):
                    continue
                responses = operation.setdefault("responses", {})
                if operation.get("security"):
                    for code, response in AUTH_RESPONSES.items():
                        responses.setdefault(code, response)
                if method.upper() in WITH_BODY and "requestBody" in operation:
                    for code, response in BODY_RESPONSES.items():
                        responses.setdefault(code, response)
        app.openapi_schema = schema
        return schema

    app.openapi = openapi  # type: ignore[method-assign]
