"""A minimal WebSocket client (RFC 6455) speaking Foxglove's protocol, for the tests."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import time
from typing import Any


class FoxgloveClient:
    """Connects to ``ws://host:port``, reads the advertised channels, subscribes
    and collects messages (topic -> list of (log time ns, payload bytes))."""

    def __init__(self, host: str, port: int, timeout_s: float = 10.0):
        self.sock = socket.create_connection((host, port), timeout=timeout_s)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET / HTTP/1.1\r\nHost: {host}:{port}\r\nUpgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                           "Sec-WebSocket-Version: 13\r\n"
                           "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError("closed during the handshake")
            head += chunk
        status, _, rest = head.partition(b"\r\n\r\n")
        if b" 101 " not in status.split(b"\r\n")[0]:
            raise ConnectionError(f"handshake refused: {status[:200]!r}")
        self.buf = rest
        self.channels: dict[int, dict[str, Any]] = {}
        self.subscribed: dict[int, str] = {}
        self.messages: dict[str, list[tuple[int, bytes]]] = {}
        self.text: list[dict[str, Any]] = []

    def _read(self, n: int) -> bytes:
        while len(self.buf) < n:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buf += chunk
        out, self.buf = self.buf[:n], self.buf[n:]
        return out

    def frame(self) -> tuple[int, bytes]:
        b0, b1 = self._read(2)
        n = b1 & 0x7F
        if n == 126:
            n = struct.unpack(">H", self._read(2))[0]
        elif n == 127:
            n = struct.unpack(">Q", self._read(8))[0]
        mask = self._read(4) if b1 & 0x80 else None
        data = self._read(n)
        if mask:
            data = bytes(c ^ mask[i % 4] for i, c in enumerate(data))
        return b0 & 0x0F, data

    def send_text(self, obj: Any) -> None:
        data = json.dumps(obj).encode()
        mask = os.urandom(4)
        n = len(data)
        head = bytes([0x81]) + (bytes([0x80 | n]) if n < 126 else
                                bytes([0x80 | 126]) + struct.pack(">H", n))
        self.sock.sendall(head + mask + bytes(c ^ mask[i % 4] for i, c in enumerate(data)))

    def pump(self) -> None:
        """Read one frame and file it."""
        op, data = self.frame()
        if op == 1:
            msg = json.loads(data)
            self.text.append(msg)
            if msg.get("op") == "advertise":
                for ch in msg["channels"]:
                    self.channels[ch["id"]] = ch
        elif op == 2 and data and data[0] == 1:
            sub, t = struct.unpack_from("<IQ", data, 1)
            topic = self.subscribed.get(sub)
            if topic is not None:
                self.messages.setdefault(topic, []).append((t, data[13:]))

    def subscribe(self, topics: list[str]) -> None:
        subs = []
        for cid, ch in self.channels.items():
            if ch["topic"] in topics and ch["topic"] not in self.subscribed.values():
                sid = len(self.subscribed) + 1
                self.subscribed[sid] = ch["topic"]
                subs.append({"id": sid, "channelId": cid})
        if subs:
            self.send_text({"op": "subscribe", "subscriptions": subs})

    def until(self, done: Any, timeout_s: float = 20.0, subscribe: list[str] = ()) -> None:
        """Pump frames until ``done(self)`` (subscribing to ``subscribe`` as they are
        advertised); TimeoutError after ``timeout_s``."""
        end = time.monotonic() + timeout_s
        while not done(self):
            if time.monotonic() > end:
                raise TimeoutError(f"waited {timeout_s} s; channels "
                                   f"{sorted(c['topic'] for c in self.channels.values())}, "
                                   f"messages {({k: len(v) for k, v in self.messages.items()})}")
            self.sock.settimeout(max(0.05, end - time.monotonic()))
            self.pump()
            self.subscribe(list(subscribe))

    def close(self) -> None:
        self.sock.close()
