"""Fan-out of one stream (telemetry, observations, link events) to many ``async for`` readers."""

from __future__ import annotations

import asyncio
import logging
from typing import Final, Generic, TypeVar

log = logging.getLogger(__name__)

T = TypeVar("T")

_END: Final = object()


class Subscription(Generic[T]):
    """One subscriber's view of a broadcast: registered when created (nothing published after
    the call is missed), read with ``async for``, released by ``aclose()`` or at the end."""

    def __init__(self, queues: set[asyncio.Queue[object]], queue_size: int, closed: bool) -> None:
        self._queues = queues
        self._queue: asyncio.Queue[object] = asyncio.Queue(queue_size)
        self._done = closed
        if not closed:
            queues.add(self._queue)

    def __aiter__(self) -> Subscription[T]:
        return self

    async def __anext__(self) -> T:
        if self._done:
            raise StopAsyncIteration
        item = await self._queue.get()
        if item is _END:
            await self.aclose()
            raise StopAsyncIteration
        return item  # type: ignore[return-value]

    async def aclose(self) -> None:
        self._done = True
        self._queues.discard(self._queue)


class Broadcast(Generic[T]):
    """Fan-out of one stream to many subscribers; a lagging one loses its oldest items."""

    def __init__(self, name: str, queue_size: int) -> None:
        self._name = name
        self._queue_size = queue_size
        self._queues: set[asyncio.Queue[object]] = set()
        self._closed = False
        self.dropped = 0

    def publish(self, item: T) -> None:
        for queue in self._queues:
            if queue.full():
                queue.get_nowait()
                self.dropped += 1
                if self.dropped == 1 or self.dropped % 100 == 0:
                    log.warning("%s: a slow subscriber lost %d items", self._name, self.dropped)
            queue.put_nowait(item)

    def close(self) -> None:
        self._closed = True
        for queue in self._queues:
            if queue.full():
                queue.get_nowait()
            queue.put_nowait(_END)

    def subscribe(self) -> Subscription[T]:
        return Subscription(self._queues, self._queue_size, self._closed)
