"""Errors of the client: a failed call carries the gRPC status code and the server's message."""

from __future__ import annotations

import contextlib
from typing import Iterator

import grpc


class GlintError(Exception):
    """A gRPC call that failed. `code` is the `grpc.StatusCode` (e.g. INVALID_ARGUMENT, whose
    message starts with the offending field, like `initial_t_w_o.translation_m.x: ...`),
    `message` the server's text, `rpc` the method called."""

    def __init__(self, rpc: str, code: grpc.StatusCode, message: str) -> None:
        self.rpc = rpc
        self.code = code
        self.message = message
        super().__init__(f"{rpc}: {code.name}: {message}")

    @property
    def code_name(self) -> str:
        """The code's name, e.g. "INVALID_ARGUMENT"."""
        return self.code.name


@contextlib.contextmanager
def calling(rpc: str) -> Iterator[None]:
    """Turns a `grpc.RpcError` raised inside into a `GlintError` naming `rpc`."""
    try:
        yield
    except grpc.RpcError as e:
        code = e.code() if callable(getattr(e, "code", None)) else grpc.StatusCode.UNKNOWN
        details = e.details() if callable(getattr(e, "details", None)) else str(e)
        raise GlintError(rpc, code, details or "") from None
