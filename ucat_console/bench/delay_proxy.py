"""A TCP proxy that delays what it carries: every chunk read from either side is written to
the other ``delay`` s later, in order (a link with that latency each way and no bandwidth
limit), the close of either side as well. It runs its own asyncio loop in a thread, listens
on a loopback port (``port``, or a free one: :attr:`DelayProxy.port`) and connects each client to
``127.0.0.1:target_port`` (the target may be down: the client's connection is then closed
after the delay, as a refused one through a slow link)."""

from __future__ import annotations

import asyncio
import threading
from typing import Any


class DelayProxy:
    def __init__(self, target_port: int, delay: float, port: int = 0) -> None:
        self.target_port = target_port
        self.delay = float(delay)
        self.port = port
        self._loop = asyncio.new_event_loop()
        self._server: Any = None
        self._tasks: set[asyncio.Task[Any]] = set()
        started = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(started,), name="delay-proxy", daemon=True)
        self._thread.start()
        started.wait(10.0)
        if not self.port:
            raise RuntimeError("the delay proxy did not start")

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"

    def _run(self, started: threading.Event) -> None:
        asyncio.set_event_loop(self._loop)

        async def start() -> None:
            self._server = await asyncio.start_server(self._client, "127.0.0.1", self.port)
            self.port = self._server.sockets[0].getsockname()[1]

        self._loop.run_until_complete(start())
        started.set()
        self._loop.run_forever()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self._tasks.add(task)
        try:
            try:
                up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.target_port)
            except OSError:
                await asyncio.sleep(self.delay)  # the refusal travels back through the link
                writer.close()
                return
            await asyncio.gather(self._pipe(reader, up_writer), self._pipe(up_reader, writer))
        except asyncio.CancelledError:  # the proxy closed: its connections end with it
            writer.close()
        finally:
            self._tasks.discard(task)

    async def _pipe(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        """Everything ``reader`` gives, written to ``writer`` ``delay`` s after it was read."""
        queue: asyncio.Queue[tuple[float, bytes]] = asyncio.Queue()
        loop = asyncio.get_running_loop()

        async def read() -> None:
            try:
                while True:
                    data = await reader.read(65536)
                    await queue.put((loop.time() + self.delay, data))
                    if not data:
                        return
            except (ConnectionError, OSError):
                await queue.put((loop.time() + self.delay, b""))

        reading = asyncio.ensure_future(read())
        try:
            while True:
                due, data = await queue.get()
                wait = due - loop.time()
                if wait > 0:
                    await asyncio.sleep(wait)
                if not data:
                    break
                writer.write(data)
                await writer.drain()
        except (ConnectionError, OSError):
            pass
        finally:
            reading.cancel()
            writer.close()

    def close(self) -> None:
        async def stop() -> None:
            self._server.close()
            for t in list(self._tasks):
                t.cancel()

        asyncio.run_coroutine_threadsafe(stop(), self._loop).result(10.0)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(10.0)
