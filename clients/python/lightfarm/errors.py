"""Errors of the lightfarm client. Their messages are the servers' own words, which are also
what the `lightfarm` CLI prints."""

import grpc


class LightfarmError(Exception):
    """Anything a lightfarm server refused or could not do."""


class Unauthenticated(LightfarmError):
    """A missing or wrong bearer token."""


class NotFound(LightfarmError):
    """An unknown job, sample or train job."""


class InvalidArgument(LightfarmError):
    """A bad dataset spec, config or request."""


class Conflict(LightfarmError):
    """The request does not fit the job's state (a cancelled job resumed, ...)."""


class Unavailable(LightfarmError):
    """The server cannot be reached (down, restarting, wrong address)."""


class ProtocolMismatch(LightfarmError):
    """The server speaks another version of the lightfarm protocol."""


_BY_CODE = {
    grpc.StatusCode.UNAUTHENTICATED: Unauthenticated,
    grpc.StatusCode.NOT_FOUND: NotFound,
    grpc.StatusCode.INVALID_ARGUMENT: InvalidArgument,
    grpc.StatusCode.FAILED_PRECONDITION: Conflict,
    grpc.StatusCode.UNAVAILABLE: Unavailable,
    grpc.StatusCode.DEADLINE_EXCEEDED: Unavailable,
}

#: Codes worth waiting out: the server restarts or the network is cut.
TRANSIENT = {
    grpc.StatusCode.UNAVAILABLE,
    grpc.StatusCode.DEADLINE_EXCEEDED,
    grpc.StatusCode.UNKNOWN,
    grpc.StatusCode.CANCELLED,
    grpc.StatusCode.ABORTED,
}


def from_rpc(e: grpc.RpcError, address: str, service: str = "coordinator") -> LightfarmError:
    """The client's exception for a failed call, worded like the CLI's error."""
    code = e.code() if hasattr(e, "code") else None
    details = e.details() if hasattr(e, "details") else str(e)
    if code in TRANSIENT:
        return Unavailable(
            f"cannot reach the {service} at {address} ({details}): is it running?"
        )
    return _BY_CODE.get(code, LightfarmError)(details)
