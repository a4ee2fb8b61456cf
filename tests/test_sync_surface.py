"""``SyncClient`` cannot drift from ``Client``: the way trio checks its
generated exports, every public method and property of the async
:class:`Client` must be on :class:`SyncClient` with the same signature
(parameter names, kinds, defaults and annotations, as strings) and carry its
docstring, except for the short, explained allow-lists below. A new public
member of ``Client`` fails here until ``SyncClient`` mirrors it or it is
listed with the reason it is not."""

from __future__ import annotations

import inspect
import re
from typing import Any

import pytest

from ros_mobile_bridge import Client, SyncClient

#: Public members of Client with no blocking namesake, and why.
NOT_MIRRORED: dict[str, str] = {
    "watch_status": "an async iterator of changes: read `status` instead, or iterate in `run()`",
    "watch_topics": "an async iterator of changes: `wait_for_topic()` is its blocking use, "
    "`topics` the snapshot, `run()` the rest",
    "watch_services": "an async iterator of changes: `wait_for_service()` is its blocking use, "
    "`services` the snapshot, `run()` the rest",
    "watch_parameters": "an async context manager yielding an async iterator: `run()`",
    "watch_server_time": "an async iterator of changes: read `server_time` instead, or `run()`",
    "watch_server_status": "an async iterator of events (each also logged): `run()`",
    "watch_playback": "an async iterator of changes: read `playback_state` instead, or `run()`",
    "record": "an async context manager that records while the caller's async code runs: `run()`",
    "serve": "an async context manager whose requests an async task answers: `run()`",
}

#: Mirrored members whose return differs in shape (parameters still match).
RESHAPED: dict[str, str] = {
    "subscribe": "an async context manager yielding a Subscription becomes a plain one "
    "yielding a SyncSubscription",
    "send_action_goal": "an async context manager yielding an ActionGoal becomes a plain one "
    "yielding a SyncActionGoal",
}

#: Public members of SyncClient that Client does not have, and why. A name
#: here that Client has too is simply checked as a mirror.
SYNC_ONLY: dict[str, str] = {
    "close": "the async client closes by leaving `async with connect()`",
    "closed": "goes with close()",
    "worker_thread": "the thread the async client runs in",
    "run": "runs `await fn(client)` in the worker: the way to everything not mirrored",
}


def public(cls: type) -> dict[str, Any]:
    return {
        name: inspect.getattr_static(cls, name) for name in dir(cls) if not name.startswith("_")
    }


def mirrored() -> list[str]:
    skip = NOT_MIRRORED.keys()
    return sorted(name for name in public(Client) if name not in skip)


MIRRORED = mirrored()


def test_every_public_member_of_client_is_on_sync_client() -> None:
    missing = [name for name in MIRRORED if name not in public(SyncClient)]
    assert not missing, f"SyncClient lacks {missing}: mirror them, or list them in NOT_MIRRORED"


def test_sync_client_has_no_unlisted_extras() -> None:
    extras = sorted(public(SyncClient).keys() - public(Client).keys() - SYNC_ONLY.keys())
    assert not extras, f"SyncClient has {extras}, which Client lacks: list them in SYNC_ONLY"


def test_the_allow_lists_name_real_members() -> None:
    client, sync = public(Client), public(SyncClient)
    assert NOT_MIRRORED.keys() <= client.keys(), "NOT_MIRRORED names what Client lacks"
    assert not NOT_MIRRORED.keys() & sync.keys(), "mirrored now: drop it from NOT_MIRRORED"
    assert RESHAPED.keys() <= set(MIRRORED)
    assert SYNC_ONLY.keys() <= sync.keys(), "SYNC_ONLY names what SyncClient lacks"


# -- one mirror ------------------------------------------------------------------
_WRAPPED = re.compile(
    r"(?:typing\.|collections\.abc\.)?(?:Awaitable\[(?P<a>.*)\]|Coroutine\[Any,Any,(?P<c>.*)\])"
)


def annotation(value: object) -> str:
    """An annotation as a comparable string: no spaces, and an awaitable or
    coroutine of X (what an async method returns) is X."""
    text = value if isinstance(value, str) else inspect.formatannotation(value)
    text = text.replace(" ", "")
    while match := _WRAPPED.fullmatch(text):
        text = match["a"] if match["a"] is not None else match["c"]
    return text


def parameters(sig: inspect.Signature) -> list[tuple[str, object, object, str]]:
    return [(p.name, p.kind, p.default, annotation(p.annotation)) for p in sig.parameters.values()]


def function_of(member: Any) -> Any:
    return member.fget if isinstance(member, property) else member


@pytest.mark.parametrize("name", MIRRORED)
def test_mirror_is_the_same_kind_of_member(name: str) -> None:
    original, sync = inspect.getattr_static(Client, name), inspect.getattr_static(SyncClient, name)
    if isinstance(original, property):
        assert isinstance(sync, property), f"SyncClient.{name} must be a property"
        assert sync.fset is None and sync.fdel is None, f"SyncClient.{name} is read-only"
    else:
        assert inspect.isfunction(original) and inspect.isfunction(sync), name
        assert not inspect.iscoroutinefunction(sync), f"SyncClient.{name} must block"
        assert not inspect.isasyncgenfunction(sync), f"SyncClient.{name} must block"


@pytest.mark.parametrize("name", MIRRORED)
def test_mirror_has_the_same_signature(name: str) -> None:
    original = inspect.signature(function_of(inspect.getattr_static(Client, name)))
    sync = inspect.signature(function_of(inspect.getattr_static(SyncClient, name)))
    theirs, ours = parameters(original), parameters(sync)
    if "timeout" in sync.parameters and "timeout" not in original.parameters:
        # the sync side adds the caller's bound on the wait: last, keyword-only,
        # None by default, and documented (in the method, or in SyncClient's
        # list of which waits are bounded)
        added = ours.pop()
        assert added == ("timeout", inspect.Parameter.KEYWORD_ONLY, None, "float|None"), (
            f"SyncClient.{name}: an added timeout is the last parameter, `*, timeout: "
            f"float | None = None`; got {added}"
        )
        own = inspect.cleandoc(function_of(inspect.getattr_static(SyncClient, name)).__doc__)
        assert "``timeout``" in own or f":meth:`{name}`" in (SyncClient.__doc__ or ""), (
            f"SyncClient.{name} adds a timeout that neither it nor SyncClient's docstring mentions"
        )
    assert ours == theirs, f"SyncClient.{name}{sync} differs from Client.{name}{original}"
    if name not in RESHAPED:
        assert annotation(sync.return_annotation) == annotation(original.return_annotation), (
            f"SyncClient.{name} returns {sync.return_annotation}, "
            f"Client.{name} {original.return_annotation}"
        )


@pytest.mark.parametrize("name", MIRRORED)
def test_mirror_carries_the_docstring(name: str) -> None:
    original = inspect.getdoc(inspect.getattr_static(Client, name))
    sync = inspect.getdoc(inspect.getattr_static(SyncClient, name))
    assert original, f"Client.{name} has no docstring"
    assert sync and original in sync, f"SyncClient.{name} does not carry Client.{name}'s docstring"
    # what static readers (the API reference) show is the sync note alone: it
    # must point to the async member whose text it carries at run time
    assert f"Client.{name}`" in sync.removeprefix(original), (
        f"SyncClient.{name}'s own docstring does not name Client.{name}"
    )
