"""How a Zenoh link is secured: :class:`ZenohSecurity` (TLS trust, a client
certificate, user/password authentication) and the check of a Zenoh
configuration source (a file or JSON5 text) held by
:attr:`ClientOptions.zenoh_config <ros_mobile_bridge.ClientOptions.zenoh_config>`.

Nothing here imports eclipse-zenoh: these are plain values, checked when
built; the session (``transport/_zenoh_link.py``) turns them into zenoh's
configuration keys when it opens."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Final

__all__ = ["ZenohSecurity", "check_zenoh_config", "describe_zenoh_config", "is_json5_text"]

_REDACTED: Final = "<redacted>"


def _path(name: str, value: object) -> str | None:
    """``value`` as a path string (None stays None); ``TypeError`` /
    ``ValueError`` naming the field ``name``."""
    if value is None:
        return None
    if not isinstance(value, str | os.PathLike):
        raise TypeError(f"{name} must be a path (str or os.PathLike) or None")
    text = os.fspath(value)
    if not isinstance(text, str):
        raise TypeError(f"{name} must be a str path, not bytes")
    if not text or "\x00" in text:
        raise ValueError(f"{name} must be a non-empty path without NUL")
    return text


@dataclass(frozen=True, slots=True, repr=False)
class ZenohSecurity:
    """The security of a Zenoh link (:attr:`ClientOptions.zenoh_security`).

    * TLS (a ``tls/host:port`` target): the router's certificate is checked
      against ``ca_file`` (PEM, one or more CA certificates), or, when it is
      None, against zenoh's built-in Web PKI roots (Mozilla's list, compiled
      into eclipse-zenoh: not this host's certificate store). With
      ``verify_name`` (the default) the certificate must also name the host
      of the target.
    * Mutual TLS: ``cert_file`` (PEM, the client's certificate chain) and
      ``key_file`` (PEM, its private key, unencrypted: zenoh reads no
      passphrase), both or neither; sent to a router that asks for a
      client certificate.
    * User/password (zenoh's ``transport/auth/usrpwd``): ``user`` and
      ``password``, both or neither, checked by the router against its
      dictionary file; over ``tcp/`` too, but only ``tls/`` encrypts the
      link.

    Paths are read when the session opens (at every reconnection), never
    here. ``password`` never appears in ``repr``, in a log line or in an
    error text of this library; the key file is read only by the TLS
    libraries. Invalid values raise ``TypeError``/``ValueError`` here,
    naming the field, never a secret's value."""

    ca_file: str | os.PathLike[str] | None = None
    """PEM file of the CA certificate(s) that sign the router's certificate;
    None: zenoh's built-in Web PKI roots."""
    cert_file: str | os.PathLike[str] | None = None
    """PEM file of this client's certificate (mutual TLS), with ``key_file``."""
    key_file: str | os.PathLike[str] | None = None
    """PEM file of the private key of ``cert_file`` (unencrypted)."""
    user: str | None = None
    """User name of zenoh's user/password authentication, with ``password``."""
    password: str | None = None
    """Password of ``user``; never shown."""
    verify_name: bool = True
    """Check that the router's certificate names the target's host (zenoh's
    ``verify_name_on_connect``). Turn off only for a router reached by an
    address its certificate does not list."""

    def __post_init__(self) -> None:
        for name in ("ca_file", "cert_file", "key_file"):
            object.__setattr__(self, name, _path(f"ZenohSecurity.{name}", getattr(self, name)))
        if (self.cert_file is None) != (self.key_file is None):
            raise ValueError("ZenohSecurity: cert_file and key_file go together (mutual TLS)")
        for name in ("user", "password"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, str):
                raise TypeError(f"ZenohSecurity.{name} must be a str or None")
        if (self.user is None) != (self.password is None):
            raise ValueError("ZenohSecurity: user and password go together")
        if self.user is not None and (not self.user or ":" in self.user or "\x00" in self.user):
            raise ValueError("ZenohSecurity.user must be non-empty, without ':' or NUL")
        if self.password is not None and (not self.password or "\x00" in self.password):
            raise ValueError("ZenohSecurity.password must be non-empty, without NUL")
        if not isinstance(self.verify_name, bool):
            raise TypeError("ZenohSecurity.verify_name must be a bool")

    @property
    def tls(self) -> bool:
        """True when a TLS setting is given (a CA or a client certificate)."""
        return self.ca_file is not None or self.cert_file is not None

    def __repr__(self) -> str:
        password = None if self.password is None else _REDACTED
        return (
            f"ZenohSecurity(ca_file={self.ca_file!r}, cert_file={self.cert_file!r}, "
            f"key_file={self.key_file!r}, user={self.user!r}, password={password!r}, "
            f"verify_name={self.verify_name!r})"
        )


def is_json5_text(source: str | os.PathLike[str]) -> bool:
    """True when ``source`` is JSON5 text rather than a file path."""
    return isinstance(source, str) and source.lstrip().startswith("{")


def check_zenoh_config(value: object) -> str | os.PathLike[str] | None:
    """``value`` checked as a Zenoh configuration source (or None): a file
    path (JSON5, JSON or YAML), or JSON5 text (a ``str`` whose first
    non-blank character is ``{``);
    ``TypeError``/``ValueError`` never quoting JSON5 text (it may hold a
    password)."""
    if value is None:
        return None
    if not isinstance(value, str | os.PathLike):
        raise TypeError(
            "zenoh_config must be a file path or JSON5 text (str or os.PathLike) or None, "
            f"not {type(value).__name__}"
        )
    if is_json5_text(value):
        return value
    _path("zenoh_config", value)  # a path: str, non-empty
    return value


def describe_zenoh_config(value: str | os.PathLike[str] | None) -> str:
    """How ``repr`` and error texts show a configuration source: a path as
    itself, JSON5 text only by its length (it may hold a password)."""
    if value is None:
        return "None"
    if is_json5_text(value):
        return f"<JSON5 text, {len(str(value))} characters>"
    return repr(os.fspath(value))
