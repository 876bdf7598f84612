"""A stand-in for tev: a TCP listener that decodes tev's IPC packets (the format of tev's ``Ipc.cpp``,
written out here independently of ``tevclient``) and keeps the images they describe."""

from __future__ import annotations

import socket
import struct
import threading
from dataclasses import dataclass, field

import numpy as np

CLOSE_IMAGE, CREATE_IMAGE, UPDATE_IMAGE_V3 = 2, 4, 6


@dataclass
class TevImageState:
    width: int
    height: int
    channel_names: list[str]
    pixels: dict[str, np.ndarray]
    updates: dict[str, int] = field(default_factory=dict)  # channel → number of update packets
    snapshots: dict[str, list[np.ndarray]] = field(default_factory=dict)  # channel → image after each


class _Reader:
    def __init__(self, payload: bytes) -> None:
        self.payload, self.offset = payload, 0

    def take(self, fmt: str) -> tuple:
        values = struct.unpack_from("<" + fmt, self.payload, self.offset)
        self.offset += struct.calcsize("<" + fmt)
        return values

    def string(self) -> str:
        end = self.payload.index(b"\0", self.offset)
        text = self.payload[self.offset : end].decode("utf-8")
        self.offset = end + 1
        return text


class TevListener:
    """Listens on a free loopback port; ``images`` maps image name → state, ``packets`` the types seen."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.port = self.server.getsockname()[1]
        self.images: dict[str, TevImageState] = {}
        self.packets: list[int] = []
        self.lock = threading.Lock()
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.close()

    def _serve(self) -> None:
        while True:
            try:
                connection, _ = self.server.accept()
            except OSError:
                return
            threading.Thread(target=self._connection, args=(connection,), daemon=True).start()

    def _connection(self, connection: socket.socket) -> None:
        buffer = b""
        with connection:
            while True:
                data = connection.recv(1 << 16)
                if not data:
                    return
                buffer += data
                while len(buffer) >= 4:
                    (length,) = struct.unpack_from("<I", buffer)
                    if len(buffer) < length:
                        break
                    self._packet(buffer[4:length])
                    buffer = buffer[length:]

    def _packet(self, payload: bytes) -> None:
        reader = _Reader(payload)
        (kind,) = reader.take("b")
        with self.lock:
            self.packets.append(kind)
            if kind == CREATE_IMAGE:
                reader.take("b")  # grab focus
                name = reader.string()
                width, height, count = reader.take("iii")
                names = [reader.string() for _ in range(count)]
                pixels = {n: np.zeros((height, width), np.float32) for n in names}
                self.images[name] = TevImageState(width, height, names, pixels)
            elif kind == UPDATE_IMAGE_V3:
                reader.take("b")
                name = reader.string()
                (count,) = reader.take("i")
                names = [reader.string() for _ in range(count)]
                x, y, width, height = reader.take("iiii")
                offsets = reader.take(f"{count}q")
                strides = reader.take(f"{count}q")
                data = np.frombuffer(payload, dtype="<f4", offset=reader.offset)
                image = self.images[name]
                pixel_index = np.arange(width * height)
                for channel, name_c in enumerate(names):
                    values = data[offsets[channel] + pixel_index * strides[channel]].reshape(height, width)
                    image.pixels[name_c][y : y + height, x : x + width] = values
                    image.updates[name_c] = image.updates.get(name_c, 0) + 1
                    image.snapshots.setdefault(name_c, []).append(image.pixels[name_c].copy())
            elif kind == CLOSE_IMAGE:
                self.images.pop(reader.string(), None)
