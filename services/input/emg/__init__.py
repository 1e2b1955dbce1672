"""``sctd input emg``: surface EMG through BrainFlow (``docs/input-emg.md``).

- :mod:`.filters`: the filter parameters (the file, the flags and the chain share them);
- :mod:`.processing`: the causal chain on arrays (band-pass, rectification, envelope,
  normalisation, axis map), free of BrainFlow;
- :mod:`.calibration`: the fit of a guided calibration and its JSON file;
- :mod:`.board`: BrainFlow's boards (the only module importing it);
- :mod:`.guided`: ``--calibrate`` in the terminal;
- :mod:`.device`: the open device the bridge reads;
- :mod:`.synthetic`: contractions with a known answer; :mod:`.bench`: the latency figure.

An EMG device moves the arm only with a calibration file: :meth:`Emg.open` refuses
without one.
"""

from __future__ import annotations

import argparse
import ctypes
import signal
import sys
import threading
from pathlib import Path

from sctd.app.options import add_arguments, from_namespace

from ..device import Backend, DeviceInfo, InputDevice, InputError
from .filters import Filters

DEFAULT_CHANNELS = 8  # the board's first EMG channels when --channels is not given


class Emg(Backend):
    name = "emg"
    help = "surface EMG through BrainFlow (synthetic, playback file or an EMG board); needs --calibration"
    library = "brainflow"
    default_map = ""
    device_axes = 3  # its calibrated axes (processing.N_AXES)
    device_buttons = 0

    def add_arguments(self, group: argparse._ArgumentGroup) -> None:
        group.add_argument("--board", default="synthetic",
                           help="BrainFlow board: synthetic, playback (with --board-file), a BoardIds "
                                "name such as CYTON_BOARD, or its id (default %(default)s)")
        group.add_argument("--board-file", metavar="FILE",
                           help="--board playback: the recording (BrainFlow DataFilter.write_file)")
        group.add_argument("--master-board", default="synthetic",
                           help="--board playback: the board whose data the file holds (default %(default)s)")
        group.add_argument("--serial-port", default="", help="the board's serial port (e.g. /dev/ttyUSB0)")
        group.add_argument("--channels", metavar="1,2,...",
                           help=f"the board's EMG channels (data rows) to use "
                                f"(default: its first {DEFAULT_CHANNELS} EMG channels)")
        group.add_argument("--calibration", metavar="FILE.json",
                           help="the calibration file to use (written by --calibrate; required)")
        group.add_argument("--calibrate", action="store_true",
                           help="run the guided calibration in the terminal and write --calibration FILE")
        group.add_argument("--force", action="store_true", help="--calibrate: overwrite the file")
        group.add_argument("--phase-seconds", type=float, default=5.0,
                           help="--calibrate: seconds recorded per phase (default %(default)s)")
        group.add_argument("--settle-seconds", type=float, default=1.0,
                           help="--calibrate: seconds dropped at the start of each phase "
                                "(default %(default)s)")
        # the filters' flags come from their one definition
        add_arguments(group, Filters, show_default=True, dest_prefix="emg_", help_prefix="--calibrate: ")

    def missing(self) -> str | None:
        from .board import missing

        return missing()

    def devices(self) -> list[DeviceInfo]:
        from .board import brainflow

        bf = brainflow()
        sid = bf.BoardIds.SYNTHETIC_BOARD.value
        rate, emg = bf.BoardShim.get_sampling_rate(sid), bf.BoardShim.get_emg_channels(sid)
        return [DeviceInfo(0, "synthetic", f"--board synthetic: BrainFlow's synthetic board, {rate} Hz, "
                                           f"EMG channels {emg[0]}..{emg[-1]}"),
                DeviceInfo(1, "playback", "--board playback --board-file FILE: a BrainFlow recording"),
                DeviceInfo(2, "board", "--board NAME --serial-port PORT: an EMG board BrainFlow supports "
                                       "(it cannot list them without opening them)")]

    def open(self, selector: str | None, args: argparse.Namespace) -> InputDevice:
        from .calibration import load
        from .device import EmgDevice

        if not getattr(args, "calibration", None):
            raise InputError("emg: no calibration: an uncalibrated EMG device must not move the arm; "
                             "run `sctd input emg --calibrate --calibration FILE` with the same --board, "
                             "then pass --calibration FILE")
        cal = load(args.calibration)
        if args.channels and _channel_list(args.channels) != cal.channels:
            raise InputError(f"emg: --channels {args.channels} differ from the calibration's "
                             f"{cal.channels} ({args.calibration}); calibrate again for them")
        return EmgDevice(_source(args), cal)

    def run_special(self, args: argparse.Namespace) -> int | None:
        if not getattr(args, "calibrate", False):
            return None
        if not args.calibration:
            raise InputError("emg --calibrate: give --calibration FILE.json to write")
        path = Path(args.calibration)
        if path.exists() and not args.force:
            raise InputError(f"emg --calibrate: {path} exists; --force to overwrite it")
        if args.phase_seconds <= args.settle_seconds:
            raise InputError(f"emg --calibrate: --phase-seconds {args.phase_seconds:g} must exceed "
                             f"--settle-seconds {args.settle_seconds:g}")
        filters = from_namespace(Filters, args, dest_prefix="emg_")
        # the bridge's handlers only set its stop event; here Ctrl-C must end the calibration.
        # The handler raises KeyboardInterrupt wherever the main thread is: inside a ctypes
        # call into BrainFlow that arrives as a ctypes.ArgumentError instead, so the flag,
        # not the exception's type, says the calibration was interrupted
        interrupted = threading.Event()

        def interrupt(*_: object) -> None:
            interrupted.set()
            raise KeyboardInterrupt

        handlers = {s: signal.signal(s, interrupt) for s in (signal.SIGINT, signal.SIGTERM)}
        try:
            return self._calibrate(args, path, filters)
        except (KeyboardInterrupt, ctypes.ArgumentError):
            if not interrupted.is_set():
                raise
            print(f"emg --calibrate: interrupted; {path} not written", file=sys.stderr)
            return 130
        finally:
            for s, h in handlers.items():
                signal.signal(s, h)

    def _calibrate(self, args: argparse.Namespace, path: Path, filters: Filters) -> int:
        from .calibration import fit, save
        from .guided import record
        from .processing import Chain

        source = _source(args)
        try:
            rows = _channels(args, source.emg_rows)
            try:
                chain = Chain(filters, source.rate_hz, len(rows))
            except ValueError as e:
                raise InputError(f"emg --calibrate: {e}") from e
            low, high = filters.band_hz(source.rate_hz)
            interactive = sys.stdin.isatty()
            _say(f"emg calibration: board {source.name}, {source.rate_hz:g} Hz, channels "
                f"{','.join(map(str, rows))}; band-pass {low:g}-{high:g} Hz, envelope "
                f"{filters.envelope_hz:g} Hz (group delay {chain.envelope_delay_s * 1e3:.1f} ms)")
            if not interactive:
                _say("stdin is not a terminal: the phases follow each other without waiting")
            envelopes = record(source, rows, chain, seconds=args.phase_seconds,
                               interactive=interactive, say=_say)
        finally:
            source.close()
        cal = fit(envelopes, board=source.name, channels=rows, rate_hz=source.rate_hz,
                  filters=filters, settle_s=args.settle_seconds)
        for note in cal.notes:
            _say(f"note: {note}")
        skip = round(args.settle_seconds * source.rate_hz)
        for name, env in envelopes.items():
            u = cal.mapping(cal.normalisation(env[skip:])).mean(axis=0)
            _say(f"check: {name:<12} -> u " + " ".join(f"{x:+.2f}" for x in u))
        save(cal, path)
        _say(f"wrote {path} (dead zone {cal.mapping.deadzone:.2f}, co-contraction rule "
            f"{'off' if cal.mapping.cocontraction is None else f'at {cal.mapping.cocontraction:.2f}'})")
        return 0


def _say(line: str) -> None:
    print(line, flush=True)


def _source(args: argparse.Namespace):
    from .board import BoardSource, BoardSpec

    return BoardSource(BoardSpec(board=args.board, file=args.board_file or "",
                                 master=args.master_board, serial_port=args.serial_port))


def _channel_list(text: str) -> list[int]:
    try:
        out = [int(c) for c in text.split(",") if c.strip()]
    except ValueError:
        raise InputError(f"emg: --channels {text!r}: give row numbers such as 1,2,3") from None
    if not out or len(set(out)) != len(out):
        raise InputError(f"emg: --channels {text!r}: give distinct row numbers")
    return out


def _channels(args: argparse.Namespace, emg_rows: list[int]) -> list[int]:
    if not args.channels:
        return emg_rows[:DEFAULT_CHANNELS]
    rows = _channel_list(args.channels)
    bad = [c for c in rows if c not in emg_rows]
    if bad:
        raise InputError(f"emg: --channels {bad} are not EMG channels of the board ({emg_rows})")
    return rows


__all__ = ["DEFAULT_CHANNELS", "Emg"]
