"""Streaming images into a running tev (https://github.com/Tom94/tev) over its TCP protocol.

``TevImage`` creates one image in tev with ``image.exr``'s channel names and replaces its pixels each
time ``show(channels)`` is called (a render's running merge after every chunk, a job's partial image as
chunks finish). tev groups channels by the part of the name before the last dot, so the image appears as
the groups ``R,G,B`` (linear sRGB), ``S0`` (the spectral bands ``S0.<λ>nm``), ``coherence`` (the
diagnostics ``coherence.l1_um`` …), ``normal`` and ``albedo``, plus ``depth``.

Packets are built by ``tevclient`` (tev's own Python client, protocol v3 ``CreateImage``/``UpdateImage``,
sent in tiles of at most 128×128 pixels).
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from typing import Any

import numpy as np

from hgcore.artifacts.layout import RGB_CHANNELS, is_spectral_channel, spectral_channel_wavelength_nm
from hgrender.cli import CliError

DEFAULT_TEV_ADDRESS: tuple[str, int] = ("127.0.0.1", 14158)  # tev's default listen address
TEV_DEFAULT = f"{DEFAULT_TEV_ADDRESS[0]}:{DEFAULT_TEV_ADDRESS[1]}"


def tev_address(text: str) -> tuple[str, int]:
    """argparse type: ``HOST:PORT``, ``HOST`` (default port) or ``:PORT`` (default host)."""
    host, _, port_text = text.rpartition(":") if ":" in text else (text, "", "")
    host = host.strip("[]") or DEFAULT_TEV_ADDRESS[0]
    if not port_text:
        return host, DEFAULT_TEV_ADDRESS[1]
    try:
        port = int(port_text)
    except ValueError:
        port = 0
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"must be HOST:PORT with a port in 1..65535, got {text!r}")
    return host, port


def add_tev_option(parser: argparse.ArgumentParser, updated: str) -> None:
    """``--tev [HOST:PORT]`` (``render`` and ``view``); ``updated`` says when tev's image is updated."""
    parser.add_argument(
        "--tev",
        nargs="?",
        const=DEFAULT_TEV_ADDRESS,
        default=None,
        type=tev_address,
        metavar="HOST:PORT",
        help=f"stream into a running tev (default address {TEV_DEFAULT}), updated {updated}",
    )


def channel_order(names: list[str]) -> list[str]:
    """``image.exr``'s channel order for tev: R, G, B first, then the bands by wavelength, then the rest
    grouped by layer."""
    rgb = [n for n in RGB_CHANNELS if n in names]
    bands = sorted((n for n in names if is_spectral_channel(n)), key=spectral_channel_wavelength_nm)
    rest = sorted(n for n in names if n not in rgb and n not in bands)
    return rgb + bands + rest


class TevImage:
    """One image in a running tev: created on the first ``show``, updated in place afterwards."""

    def __init__(self, address: tuple[str, int], name: str) -> None:
        self.address = address
        self.name = name
        self._ipc: Any = None
        self._created: tuple[int, int, tuple[str, ...]] | None = None

    def __enter__(self) -> TevImage:
        import tevclient

        host, port = self.address
        ipc = tevclient.Ipc(host, port)
        try:
            ipc.__enter__()
        except OSError as error:
            reason = error.strerror or str(error) or type(error).__name__
            raise CliError(
                f"tev: no tev listening at {host}:{port} ({reason.lower()}); start tev first "
                f"(it listens on {TEV_DEFAULT} by default) or pass --tev HOST:PORT"
            ) from None
        self._ipc = ipc
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self._ipc is not None:
            self._ipc.__exit__(None, None, None)
            self._ipc = None

    def show(self, channels: Mapping[str, np.ndarray]) -> None:
        """Send every channel (name → (H, W) array): a new image the first time (or when the size or the
        channel set changed), pixel updates of the existing one after that."""
        if not channels:
            return
        names = channel_order(list(channels))
        height, width = np.shape(channels[names[0]])
        try:
            if self._created != (width, height, tuple(names)):
                if self._created is not None:
                    self._ipc.close_image(self.name)
                self._ipc.create_image(self.name, width, height, names, grab_focus=True)
                self._created = (width, height, tuple(names))
            for group in channel_groups(names):
                tile = np.stack([np.asarray(channels[n], dtype=np.float32) for n in group], axis=-1)
                self._ipc.update_image(self.name, tile, group)
        except OSError as error:
            host, port = self.address
            reason = error.strerror or str(error) or type(error).__name__
            raise CliError(f"tev: the connection to {host}:{port} broke ({reason.lower()})") from None


def channel_groups(names: list[str]) -> list[list[str]]:
    """Channels grouped by tev layer (the name up to its last dot; ``R``/``G``/``B``/``depth``: the root
    layer), in the order given: one update packet series per group."""
    groups: dict[str, list[str]] = {}
    for name in names:
        groups.setdefault(name.rpartition(".")[0], []).append(name)
    return list(groups.values())
