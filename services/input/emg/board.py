"""BrainFlow's boards as a source of EMG samples (the only module that imports it).

Only boards that need no network are meant here: the synthetic board, the playback-file
board and the serial/Bluetooth EMG boards. BrainFlow's streaming boards open multicast
sockets and are refused.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np

from ..device import InputError

MISSING = "needs brainflow: pip install 'sctd[inputs]'"
NETWORKED = ("STREAMING_BOARD",)  # BrainFlow boards that open network sockets


def brainflow() -> Any:
    """BrainFlow's modules, imported quietly (on Python 3.11 its board_shim warns about
    ``pkg_resources`` when it loads its libraries) with its loggers off."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        warnings.simplefilter("ignore", DeprecationWarning)
        from brainflow.board_shim import BoardIds, BoardShim, BrainFlowError, BrainFlowInputParams
        from brainflow.data_filter import DataFilter

        BoardShim.disable_board_logger()
        DataFilter.disable_data_logger()
    return SimpleNamespace(BoardIds=BoardIds, BoardShim=BoardShim, BrainFlowError=BrainFlowError,
                           BrainFlowInputParams=BrainFlowInputParams, DataFilter=DataFilter)


def missing() -> str | None:
    try:
        brainflow()
    except ImportError:
        return MISSING
    except Exception as e:  # its library does not load
        return f"brainflow does not load: {e}"
    return None


def board_id(name: str) -> int:
    """The BrainFlow board id of ``name``: ``synthetic``, ``playback``, a BoardIds name
    (``CYTON_BOARD``, case-insensitive) or its number."""
    bf = brainflow()
    aliases = {"synthetic": "SYNTHETIC_BOARD", "playback": "PLAYBACK_FILE_BOARD"}
    key = aliases.get(name.lower(), name.upper())
    if name.lstrip("-").isdigit():
        try:
            key = bf.BoardIds(int(name)).name
        except ValueError:
            raise InputError(f"emg: --board {name}: no BrainFlow board has that id") from None
    if key in NETWORKED:
        raise InputError(f"emg: --board {name}: streaming boards open network sockets; not supported")
    try:
        return int(bf.BoardIds[key].value)
    except KeyError:
        raise InputError(f"emg: --board {name!r}: not a BrainFlow board (synthetic, playback, or a "
                         f"BoardIds name such as CYTON_BOARD)") from None


@dataclass(frozen=True)
class BoardSpec:
    """Which board to open and how: what ``--board``, ``--board-file``, ``--master-board``
    and ``--serial-port`` say."""

    board: str = "synthetic"
    file: str = ""
    master: str = "synthetic"
    serial_port: str = ""


class BoardSource:
    """An open BrainFlow board streaming; :meth:`poll` returns what arrived since the last
    call without blocking.

    Attributes
    ----------
    rate_hz : float
        The sampling rate (the master board's for a playback file).
    emg_rows : list of int
        The board's EMG channels (data rows).
    rows : int
        Rows per sample in the board's layout (what a playback file must hold).
    """

    def __init__(self, spec: BoardSpec):
        bf = brainflow()
        self.spec = spec
        bid = board_id(spec.board)
        params = bf.BrainFlowInputParams()
        described = bid
        if bid == bf.BoardIds.PLAYBACK_FILE_BOARD.value:
            if not spec.file:
                raise InputError("emg: --board playback needs --board-file FILE (written by "
                                 "DataFilter.write_file)")
            params.file = spec.file
            described = board_id(spec.master)
            params.master_board = described
        if spec.serial_port:
            params.serial_port = spec.serial_port
        self.board_id = bid
        self.name = spec.board if not spec.file else f"{spec.board}:{spec.file}"
        try:
            self.rate_hz = float(bf.BoardShim.get_sampling_rate(described))
            self.emg_rows = list(bf.BoardShim.get_emg_channels(described))
            self.rows = int(bf.BoardShim.get_num_rows(described))
        except bf.BrainFlowError as e:
            raise InputError(f"emg: board {spec.board}: has no EMG channels ({e})") from e
        self._shim = bf.BoardShim(bid, params)
        self._error = bf.BrainFlowError
        try:
            self._shim.prepare_session()
            self._shim.start_stream()
        except bf.BrainFlowError as e:
            self._release()
            raise InputError(f"emg: board {self.name}: cannot start: {e}") from e
        self.started = time.monotonic()

    def poll(self, rows: list[int]) -> np.ndarray:
        """The samples (n, len(rows)) that arrived since the last call; n may be 0."""
        data = self._shim.get_board_data()
        return np.ascontiguousarray(data[rows].T)

    def flush(self) -> None:
        """Drop what arrived so far."""
        self._shim.get_board_data()

    def close(self) -> None:
        if self._shim is not None:
            try:
                self._shim.stop_stream()
            except self._error:
                pass
            self._release()

    def _release(self) -> None:
        try:
            self._shim.release_session()
        except self._error:
            pass
        self._shim = None


def write_playback(path: str, samples: np.ndarray, rows: list[int], rate_hz: float,
                   master: str = "synthetic", start: float | None = None) -> None:
    """Write ``samples`` (n, len(rows)) as a playback file in ``master``'s row layout, with
    timestamps at ``rate_hz`` from ``start`` (default: now), by DataFilter.write_file."""
    bf = brainflow()
    bid = board_id(master)
    data = np.zeros((bf.BoardShim.get_num_rows(bid), samples.shape[0]))
    data[rows] = samples.T
    t0 = time.time() if start is None else start
    data[bf.BoardShim.get_timestamp_channel(bid)] = t0 + np.arange(samples.shape[0]) / rate_hz
    bf.DataFilter.write_file(data, path, "w")
