"""The Zenoh link before the session: the zenoh configuration of a client
session (a user's configuration, then the library's keys and
:class:`~ros_mobile_bridge.ZenohSecurity` on top), and a probe of the
router's link that names why a secure link fails.

Why a probe: eclipse-zenoh's ``open`` reports every failed link the same
way (``Unable to connect to any of [...] Timeout!``) after retrying until
``connect/timeout_ms``: an untrusted router certificate, a client
certificate the router refuses or lacks, and a refused password all read
alike, and their causes go only to zenoh's own Rust log. So before zenoh
opens a ``tls/`` link (or any link with user/password), :func:`probe_link`
opens one TCP connection to the router, makes the TLS handshake with the
same CA, client certificate and name check, sends one byte zenoh does not
accept as a handshake (the router answers with a ``Close`` and hangs up)
and reads until the router closes: a TLS alert on the way (``certificate
required``, ``unknown ca``...) names the client-certificate failure. No
wait for time: every step ends on the router's answer or the deadline.
When the probe passes and zenoh still cannot open, what is left is the
zenoh handshake itself, where user/password authentication happens
(:func:`explain_open_failure`).

The probe reads the TLS settings from the final zenoh configuration, so it
checks what zenoh will use, the user's configuration file included. Its
own TLS library (OpenSSL through :mod:`ssl`) is not zenoh's (rustls):
with no CA file the probe trusts this host's store while zenoh trusts its
built-in Web PKI roots; a router certificate one trusts and the other does
not then passes the probe and fails in zenoh, reported as a failed
handshake."""

from __future__ import annotations

import contextlib
import json
import os
import re
import socket
import ssl
from dataclasses import dataclass
from typing import Any, Final

from .._errors import ConnectError, NotSupportedError
from .._zenoh_options import ZenohSecurity, describe_zenoh_config, is_json5_text

__all__ = ["LinkSettings", "explain_open_failure", "load_zenoh", "probe_link", "session_config"]

_EXTRA_HINT: Final = "pip install 'ros-mobile-bridge[zenoh]'"

_NOT_ZENOH_HANDSHAKE: Final = b"\x01\x00\x00"
"""A streamed zenoh frame (16-bit little-endian length, then the message)
holding one byte that is no handshake message: a router answers it with a
``Close`` and hangs up."""
_POSITION: Final = re.compile(r"-->\s*(\d+:\d+)")
_UNKNOWN_FIELD: Final = re.compile(r"unknown field `[^`]{1,64}`")
_CLIENT_CERT_ALERTS: Final = {
    "TLSV13_ALERT_CERTIFICATE_REQUIRED": "the router requires a client certificate",
    "TLSV1_ALERT_UNKNOWN_CA": "the router does not trust the client certificate's CA",
    "SSLV3_ALERT_BAD_CERTIFICATE": "the router rejected the client certificate",
    "SSLV3_ALERT_CERTIFICATE_UNKNOWN": "the router rejected the client certificate",
    "SSLV3_ALERT_CERTIFICATE_EXPIRED": "the router says the client certificate has expired",
    "SSLV3_ALERT_CERTIFICATE_REVOKED": "the router says the client certificate is revoked",
    "SSLV3_ALERT_UNSUPPORTED_CERTIFICATE": "the router does not support the client certificate",
    "TLSV1_ALERT_DECRYPT_ERROR": "the router could not verify the client certificate's key",
    "TLSV1_ALERT_ACCESS_DENIED": "the router denied access to the client certificate",
}


def load_zenoh() -> Any:
    """The ``zenoh`` module, or ``NotSupportedError`` naming the extra."""
    try:
        import zenoh
    except ImportError as exc:
        raise NotSupportedError(
            f"the zenoh transport needs eclipse-zenoh, which is not installed: {_EXTRA_HINT}"
        ) from exc
    return zenoh


def _load_source(z: Any, source: str | os.PathLike[str] | None) -> Any:
    """A ``zenoh.Config`` read from ``source`` (a fresh one for None);
    ``ConnectError`` naming the file, or the position in JSON5 text, never
    quoting the text (it may hold a password)."""
    if source is None:
        return z.Config()
    shown = describe_zenoh_config(source)
    try:
        if is_json5_text(source):
            return z.Config.from_json5(str(source))
        path = os.fspath(source)
        if not os.path.isfile(path):
            raise ConnectError(f"zenoh: the configuration file {path!r} does not exist")
        return z.Config.from_file(path)
    except z.ZError as exc:
        text = str(exc)
        where = _POSITION.search(text)
        field = _UNKNOWN_FIELD.search(text)
        detail = (
            f"at line:column {where.group(1)}"
            if where
            else (field.group(0) if field else "zenoh could not read it")
        )
        # not chained: zenoh's message quotes the offending line
        raise ConnectError(
            f"zenoh: invalid configuration {shown}: {detail} (its text is not shown: it "
            "may hold a secret)"
        ) from None


def _insert(config: Any, key: str, value: object) -> None:
    """Set ``key`` to ``value`` (JSON); a key zenoh refuses raises
    ``ConnectError`` naming the key only."""
    try:
        config.insert_json5(key, json.dumps(value))
    except Exception:
        raise ConnectError(f"zenoh: cannot set {key} in the configuration") from None


def session_config(
    endpoint: str,
    *,
    connect_timeout: float,
    shared_memory: bool,
    security: ZenohSecurity | None = None,
    source: str | os.PathLike[str] | None = None,
) -> Any:
    """The ``zenoh.Config`` of a *client* session to the router at
    ``endpoint``: ``source`` read first (a file or JSON5 text), then the
    library's keys (client mode: it fails at once when the router is
    unreachable, where peer mode would open against a dead endpoint and
    lose early puts; the endpoint; the timeout; no multicast scouting nor
    gossip; shared memory off unless asked, as rmw_zenoh configures its
    sessions), then each field of ``security`` that is set. Every other key
    keeps ``source``'s value."""
    z = load_zenoh()
    config = _load_source(z, source)
    _insert(config, "mode", "client")
    _insert(config, "connect/endpoints", [endpoint])
    _insert(config, "connect/timeout_ms", max(int(connect_timeout * 1000), 1))
    _insert(config, "scouting/multicast/enabled", False)
    _insert(config, "scouting/gossip/enabled", False)
    _insert(config, "transport/shared_memory/enabled", shared_memory)
    if security is not None:
        tls = "transport/link/tls/"
        if security.ca_file is not None:
            _insert(config, tls + "root_ca_certificate", security.ca_file)
        if security.cert_file is not None:
            _insert(config, tls + "enable_mtls", True)
            _insert(config, tls + "connect_certificate", security.cert_file)
            _insert(config, tls + "connect_private_key", security.key_file)
        if not security.verify_name:
            _insert(config, tls + "verify_name_on_connect", False)
        if security.user is not None:
            _insert(config, "transport/auth/usrpwd/user", security.user)
            _insert(config, "transport/auth/usrpwd/password", security.password)
    return config


def _get(config: Any, key: str) -> Any:
    try:
        return json.loads(config.get_json(key))
    except Exception:
        return None


@dataclass(frozen=True, slots=True)
class LinkSettings:
    """What the probe needs, read back from a session's final configuration
    (so a user's configuration file counts): never the password itself."""

    host: str
    port: int
    tls: bool
    ca_file: str | None
    ca_inline: bool
    """The CA is given as base64 in the configuration (not probed)."""
    cert_file: str | None
    key_file: str | None
    cert_inline: bool
    """The client certificate or key is given as base64 (not probed)."""
    verify_name: bool
    user: str | None
    """The user of zenoh's user/password authentication, when configured."""

    @classmethod
    def read(cls, endpoint: str, config: Any) -> LinkSettings | None:
        """The settings of ``endpoint`` (``tcp/`` or ``tls/host:port``) and
        ``config``; None for an endpoint of another form."""
        proto, _, address = endpoint.partition("/")
        address = address.split("#", 1)[0].split("?", 1)[0]
        host, sep, port_text = address.rpartition(":")
        if proto not in ("tcp", "tls") or not sep or not port_text.isdigit():
            return None
        tls = "transport/link/tls/"
        mtls = _get(config, tls + "enable_mtls") is True
        user = _get(config, "transport/auth/usrpwd/user")
        return cls(
            host=host.strip("[]"),
            port=int(port_text),
            tls=proto == "tls",
            ca_file=_get(config, tls + "root_ca_certificate"),
            ca_inline=_get(config, tls + "root_ca_certificate_base64") is not None,
            cert_file=_get(config, tls + "connect_certificate") if mtls else None,
            key_file=_get(config, tls + "connect_private_key") if mtls else None,
            cert_inline=mtls
            and (
                _get(config, tls + "connect_certificate_base64") is not None
                or _get(config, tls + "connect_private_key_base64") is not None
            ),
            verify_name=_get(config, tls + "verify_name_on_connect") is not False,
            user=user if isinstance(user, str) else None,
        )

    def describe(self) -> str:
        """The link's security in words, for a debug log (no secret)."""
        parts = [
            "TLS, CA "
            + (repr(self.ca_file) if self.ca_file else "built-in roots")
            + (f", client certificate {self.cert_file!r}" if self.cert_file else "")
            if self.tls
            else "plain TCP"
        ]
        if self.user is not None:
            parts.append(f"user {self.user!r} with a password")
        return ", ".join(parts)

    @property
    def probed(self) -> bool:
        """Whether :func:`probe_link` checks this link: a TLS link whose
        settings are files, or any link with user/password (to tell an
        unreachable router from a refused password)."""
        if self.tls:
            return not (self.ca_inline or self.cert_inline)
        return self.user is not None


def _no_passphrase() -> bytes:
    """The passphrase callback of ``load_cert_chain``: none (zenoh reads no
    encrypted key; without a callback OpenSSL would prompt on the terminal)."""
    return b""


def _tls_context(link: LinkSettings, locator: str) -> ssl.SSLContext:
    """The probe's TLS context, as zenoh will use the files; ``ConnectError``
    naming the file that cannot be read (never its content)."""
    try:
        context = ssl.create_default_context(cafile=link.ca_file)
    except (OSError, ssl.SSLError) as exc:
        raise ConnectError(
            f"zenoh: TLS to {locator}: cannot read the CA file {link.ca_file!r}: {_reason(exc)}"
        ) from None
    context.minimum_version = ssl.TLSVersion.TLSv1_2
    context.check_hostname = link.verify_name
    if link.cert_file is not None and link.key_file is not None:
        try:
            context.load_cert_chain(link.cert_file, link.key_file, password=_no_passphrase)
        except (OSError, ssl.SSLError) as exc:
            raise ConnectError(
                f"zenoh: TLS to {locator}: cannot use the client certificate "
                f"{link.cert_file!r} with the key {link.key_file!r}: {_reason(exc)}"
            ) from None
    return context


def _reason(exc: BaseException) -> str:
    """A TLS or OS error as text without a file's content: OpenSSL's
    reason, or ``strerror``."""
    if isinstance(exc, ssl.SSLCertVerificationError):
        return str(exc.verify_message or exc.reason or "certificate verify failed")
    if isinstance(exc, ssl.SSLError):
        return str(exc.reason or exc.strerror or type(exc).__name__)
    if isinstance(exc, OSError):
        return str(exc.strerror or type(exc).__name__)
    return type(exc).__name__


def probe_link(link: LinkSettings, locator: str, timeout: float) -> None:
    """Check the router's link as zenoh will open it (blocking; every step
    bounded by ``timeout`` seconds), raising ``ConnectError`` with the
    cause: the router unreachable, its certificate not trusted or not
    naming the host, a client certificate it requires or refuses, or (a
    ``tls/`` target) a router that does not speak TLS. Returns when the
    router took the link and answered the probe byte as a zenoh router
    does."""
    context = _tls_context(link, locator) if link.tls else None
    try:
        raw = socket.create_connection((link.host, link.port), timeout=max(timeout, 0.001))
    except TimeoutError:
        raise ConnectError(f"zenoh: no answer from {locator} within the timeout") from None
    except OSError as exc:
        raise ConnectError(f"zenoh: cannot reach a router at {locator}: {_reason(exc)}") from None
    with raw:
        stream: socket.socket = raw
        if context is not None:
            try:
                stream = context.wrap_socket(raw, server_hostname=link.host)
            except ssl.SSLCertVerificationError as exc:
                trust = f"the CA file {link.ca_file!r}" if link.ca_file else "the system's roots"
                raise ConnectError(
                    f"zenoh: TLS to {locator}: the router's certificate is not trusted: "
                    f"{_reason(exc)} (checked against {trust}; ZenohSecurity.ca_file)"
                ) from None
            except ssl.SSLError as exc:
                raise ConnectError(
                    f"zenoh: TLS to {locator}: the TLS handshake failed: {_reason(exc)}"
                    " (is the router listening on a tls/ endpoint there?)"
                ) from None
            except TimeoutError:
                raise ConnectError(
                    f"zenoh: TLS to {locator}: no TLS handshake within the timeout"
                ) from None
            except OSError as exc:
                raise ConnectError(
                    f"zenoh: TLS to {locator}: the router closed the TLS handshake: "
                    f"{_reason(exc)} (is it listening on a tls/ endpoint there?)"
                ) from None
        with contextlib.closing(stream):  # (the TLS socket took raw's descriptor)
            _answer_of_router(stream, link, locator)


def _answer_of_router(stream: socket.socket, link: LinkSettings, locator: str) -> None:
    """Send the probe byte and read until the router hangs up; a TLS alert
    meanwhile names a refused client certificate."""
    try:
        stream.sendall(_NOT_ZENOH_HANDSHAKE)
        while stream.recv(4096):
            pass
    except ssl.SSLError as exc:
        reason = str(exc.reason or "")
        cause = _CLIENT_CERT_ALERTS.get(reason)
        if cause is None:
            raise ConnectError(
                f"zenoh: TLS to {locator}: the router ended the TLS link: {_reason(exc)}"
            ) from None
        if link.cert_file is None:
            raise ConnectError(
                f"zenoh: TLS to {locator}: {cause} (mutual TLS) and none is configured: "
                "set ZenohSecurity(cert_file=..., key_file=...)"
            ) from None
        raise ConnectError(
            f"zenoh: TLS to {locator}: {cause} {link.cert_file!r} ({_reason(exc)})"
        ) from None
    except TimeoutError:
        raise ConnectError(
            f"zenoh: {locator} took the link but did not answer as a zenoh router within "
            "the timeout"
        ) from None
    except OSError:
        return  # reset by the router after its Close: it answered


def explain_open_failure(link: LinkSettings | None, locator: str, error: str) -> str:
    """The ``ConnectError`` text of a zenoh ``open`` that failed with
    ``error`` after the probe of ``link`` passed (or was not made)."""
    if link is None or not link.probed:
        return f"zenoh: cannot reach a router at {locator}: {error}"
    checked = "the TLS link was accepted" if link.tls else "the router answers"
    if link.user is not None:
        return (
            f"zenoh: authentication failed: the router at {locator} refused the session of "
            f"user {link.user!r} ({checked}; the zenoh handshake was refused): wrong user or "
            f"password, or a user the router does not know ({error})"
        )
    return (
        f"zenoh: the router at {locator} refused the session ({checked}; the zenoh "
        "handshake was refused): a router that requires authentication needs "
        f"ZenohSecurity(user=..., password=...) ({error})"
    )
