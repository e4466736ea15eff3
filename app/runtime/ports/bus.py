"""The bus port: a publish/subscribe client with MQTT topic semantics, as the loops use it.

Both buses (``app.adapters.bus``: in-process and MQTT) implement it; the messages and topics
they carry are ``app.runtime.ports.messages`` and ``app.runtime.ports.topics``.
"""

from types import TracebackType
from typing import Protocol, Self

from app.runtime.ports.messages import Message
from app.runtime.ports.topics import Topic, TopicFilter


class Subscription(Protocol):
    """The messages on one topic filter: enter it, then ``async for topic, message in it``."""

    dropped: int
    """Messages pushed out of its full queue by newer ones, never read."""

    async def __aenter__(self) -> Self: ...

    async def __aexit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None: ...

    def __aiter__(self) -> Self: ...

    async def __anext__(self) -> tuple[Topic, Message]: ...

    def drain(self) -> list[tuple[Topic, Message]]:
        """Every message queued, oldest first, without waiting."""
        ...


class Bus(Protocol):
    """One bus client: publish a message on a topic; subscribe to a topic filter."""

    async def publish(
        self,
        topic: Topic | str,
        message: Message,
        *,
        qos: int | None = None,
        retain: bool = False,
    ) -> None: ...

    def subscribe(
        self, topic_filter: TopicFilter | Topic | str, *, queue_size: int | None = None
    ) -> Subscription: ...
