"""Who the client is and how it talks to a secured Glint deployment: a bearer token sent as
`authorization: Bearer <token>` on every call, and TLS (the CA that signed the servers'
certificates, and optionally a client certificate for servers that require one).

The token never appears in a message, a `repr` or a log: errors name the file it came from."""

from __future__ import annotations

import os
from typing import Any, Callable, Optional, Union

import grpc

PathLike = Union[str, "os.PathLike[str]"]


class SecurityConfigError(ValueError):
    """A token or TLS file that cannot be used (missing, unreadable, empty, not PEM, …), or
    settings that do not go together; the message names the file, never the token."""


def _read(path: PathLike, what: str) -> bytes:
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        raise SecurityConfigError(f"{what} {os.fspath(path)}: {e.strerror or e}") from None


def check_token(token: str, source: str = "the token") -> str:
    """`token` with surrounding whitespace trimmed; it must be non-empty printable ASCII (it
    travels in an HTTP/2 header), as Glint's servers require of theirs."""
    secret = token.strip()
    if not secret:
        raise SecurityConfigError(f"{source} is empty")
    if not all(" " <= c <= "~" for c in secret):
        raise SecurityConfigError(f"{source}: the token must be printable ASCII (no tabs, line breaks or non-ASCII)")
    return secret


def read_token_file(path: PathLike) -> str:
    """The token held in the file at `path`, surrounding whitespace trimmed."""
    raw = _read(path, "token file")
    where = f"token file {os.fspath(path)}"
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise SecurityConfigError(f"{where}: not UTF-8 text") from None
    return check_token(text, where)


def _read_pem(path: PathLike, what: str) -> bytes:
    pem = _read(path, what)
    if b"-----BEGIN " not in pem:
        raise SecurityConfigError(f"{what} {os.fspath(path)}: not a PEM file (no -----BEGIN line)")
    return pem


def channel_credentials(
    tls_ca: Optional[PathLike], tls_cert: Optional[PathLike] = None, tls_key: Optional[PathLike] = None
) -> Optional[grpc.ChannelCredentials]:
    """TLS credentials trusting the CA in `tls_ca` (PEM), presenting the client certificate
    `tls_cert` with its key `tls_key` when given; None (plaintext) without `tls_ca`."""
    if (tls_cert is None) != (tls_key is None):
        raise SecurityConfigError("tls_cert and tls_key go together (a client certificate and its private key)")
    if tls_ca is None:
        if tls_cert is not None:
            raise SecurityConfigError("a client certificate needs TLS: give tls_ca, the CA of the servers' certificates")
        return None
    root = _read_pem(tls_ca, "TLS CA file")
    cert = _read_pem(tls_cert, "TLS certificate file") if tls_cert is not None else None
    key = _read_pem(tls_key, "TLS key file") if tls_key is not None else None
    return grpc.ssl_channel_credentials(root_certificates=root, private_key=key, certificate_chain=cert)


class _ClientCallDetails(grpc.ClientCallDetails):
    def __init__(self, details: grpc.ClientCallDetails, metadata: Any) -> None:
        self.method = details.method
        self.timeout = details.timeout
        self.metadata = metadata
        self.credentials = details.credentials
        self.wait_for_ready = getattr(details, "wait_for_ready", None)
        self.compression = getattr(details, "compression", None)


class BearerToken(
    grpc.UnaryUnaryClientInterceptor,
    grpc.UnaryStreamClientInterceptor,
    grpc.StreamUnaryClientInterceptor,
    grpc.StreamStreamClientInterceptor,
):
    """A client interceptor adding `authorization: Bearer <token>` to every call's metadata
    (plaintext or TLS alike)."""

    def __init__(self, token: str) -> None:
        self.__metadata = ("authorization", "Bearer " + check_token(token))

    def __repr__(self) -> str:
        return "BearerToken(<redacted>)"

    def _with_token(self, details: grpc.ClientCallDetails) -> grpc.ClientCallDetails:
        metadata = [(k, v) for k, v in (details.metadata or ()) if k.lower() != "authorization"]
        metadata.append(self.__metadata)
        return _ClientCallDetails(details, metadata)

    def intercept_unary_unary(self, continuation: Callable, client_call_details: Any, request: Any) -> Any:
        return continuation(self._with_token(client_call_details), request)

    def intercept_unary_stream(self, continuation: Callable, client_call_details: Any, request: Any) -> Any:
        return continuation(self._with_token(client_call_details), request)

    def intercept_stream_unary(self, continuation: Callable, client_call_details: Any, request_iterator: Any) -> Any:
        return continuation(self._with_token(client_call_details), request_iterator)

    def intercept_stream_stream(self, continuation: Callable, client_call_details: Any, request_iterator: Any) -> Any:
        return continuation(self._with_token(client_call_details), request_iterator)


def resolve_token(token: Optional[str], token_file: Optional[PathLike]) -> Optional[str]:
    """The token from `token` or from `token_file` (not both); None for none."""
    if token is not None and token_file is not None:
        raise SecurityConfigError("give token or token_file, not both")
    if token_file is not None:
        return read_token_file(token_file)
    if token is not None:
        return check_token(token)
    return None
