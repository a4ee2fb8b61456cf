"""The way out: the outbox (control frames first, the newest per topic, then
data frames in order), the receipts that tell a control publish its frame was
written, and the writes themselves. The connection runs the writer task and
says which adapter is current; nothing here knows a protocol."""

from __future__ import annotations

from collections.abc import Awaitable, Callable

import anyio

from .._errors import ConnectError
from ..adapters import Adapter
from ..flow import Outbox, WireMessage

__all__ = ["Outbound", "Receipt"]


class Receipt:
    """The fate of one control publish: settled once its frame, or the newer
    value for the same topic that replaced it in the outbox, is written to
    the socket (``error`` None), or once it cannot be (``error`` says why)."""

    __slots__ = ("covers", "done", "error")

    def __init__(self) -> None:
        self.done = anyio.Event()
        self.error: ConnectError | None = None
        self.covers: list[Receipt] = []
        """Older receipts for the same topic whose frames this one replaced."""

    def absorb(self, older: Receipt) -> None:
        """This receipt's frame replaced ``older``'s: settle them together."""
        self.covers.append(older)
        self.covers.extend(older.covers)
        older.covers = []

    def settle(self, error: ConnectError | None) -> None:
        for receipt in (self, *self.covers):
            receipt.error = error
            receipt.done.set()
        self.covers = []


class Outbound:
    """The outbox and its receipts. :attr:`adapter` is the connection that
    writes (set by the connection on every (re)connect, None while there is
    none)."""

    def __init__(self, adapter: Adapter) -> None:
        self.outbox = Outbox()
        self.adapter: Adapter | None = adapter
        self._receipts: dict[str, tuple[WireMessage, Receipt]] = {}  # control frames queued
        self._writing = False
        self._wrote = anyio.Event()  # set after each frame the writer sends

    # -- control ---------------------------------------------------------------
    def queue_control(self, topic: str, message: WireMessage) -> Receipt:
        """Put a control frame in the outbox; its receipt settles when it (or
        a newer value for ``topic``) is written, or cannot be."""
        receipt = Receipt()
        queued = self._receipts.get(topic)
        if queued is not None:  # still unsent: the outbox replaces it
            receipt.absorb(queued[1])
        self.outbox.put_control(topic, message)
        self._receipts[topic] = (message, receipt)
        return receipt

    async def send_control(self) -> None:
        """Write every queued control frame now (the writer task would only
        get to them on its next turn). Raises ``ConnectError`` when a write
        fails: the connection is lost (the reader handles that)."""
        adapter = self.adapter
        if adapter is None:
            raise ConnectError("not connected")
        outbox = self.outbox
        while (message := outbox.pop_control()) is not None:
            await self.write_taken(adapter, message)

    async def publish_control(self, topic: str, message: WireMessage) -> ConnectError | None:
        """Queue a control frame, then write it at once (not behind the
        writer's or the reader's next turn; control frames queued meanwhile
        go first). Returns once this frame, or a newer value for ``topic``
        that replaced it, is written (another task may be writing it): None,
        or the error that kept it from the socket."""
        receipt = self.queue_control(topic, message)
        try:
            await self.send_control()
        except ConnectError as exc:  # lost: before this frame's turn, or on it
            return receipt.error if receipt.done.is_set() else exc
        await receipt.done.wait()
        return receipt.error

    async def write_taken(self, adapter: Adapter, message: WireMessage) -> None:
        """Write ``message``, just taken from the outbox, and settle its
        receipt if it is a control frame. Cancelled before the write began
        (a write, once begun, is finished), a control frame goes back to the
        outbox unless a newer value for its topic is queued already."""
        taken: tuple[str, Receipt] | None = None
        if self._receipts:
            for topic, (queued, receipt) in self._receipts.items():
                if queued is message:
                    del self._receipts[topic]
                    taken = topic, receipt
                    break
        try:
            await adapter.send(message)
        except ConnectError as exc:
            if taken is not None:
                taken[1].settle(exc)
            raise
        except BaseException:
            if taken is not None:
                topic, receipt = taken
                newer = self._receipts.get(topic)
                if newer is not None:
                    newer[1].absorb(receipt)
                elif adapter is self.adapter:
                    self.outbox.put_control(topic, message)
                    self._receipts[topic] = (message, receipt)
                else:
                    receipt.settle(ConnectError("the connection closed before it was written"))
            raise
        if taken is not None:
            taken[1].settle(None)

    def settle_all(self, error: ConnectError) -> None:
        """Every control publish still waiting raises ``error``: its frame
        will not be written."""
        receipts, self._receipts = self._receipts, {}
        for _message, receipt in receipts.values():
            receipt.settle(error)

    # -- the writer --------------------------------------------------------------
    async def run_writer(
        self, next_connection: Callable[[Adapter | None], Awaitable[bool]]
    ) -> None:
        """The writer task: send what the outbox gives. After a failed write
        (or with no connection), wait for ``next_connection`` to be up (False:
        the client is done)."""
        outbox = self.outbox
        while True:
            message = await outbox.get()
            adapter = self.adapter
            self._writing = True  # a frame taken from the outbox is not lost
            try:
                if adapter is None:
                    raise ConnectError("not connected")
                await self.write_taken(adapter, message)
            except ConnectError:
                if not await next_connection(adapter):
                    return
            finally:
                self._writing = False
                self._wrote.set()

    async def drain(self, budget: float) -> None:
        """Let the writer send what is queued (control first, then data) and
        finish the frame it holds, for at most ``budget`` seconds."""
        with anyio.move_on_after(budget):
            while len(self.outbox) or self._writing:
                self._wrote = anyio.Event()
                await self._wrote.wait()
