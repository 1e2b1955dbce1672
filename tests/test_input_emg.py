"""The EMG backend: the chain's known answers on arrays, the calibration's known answer
through BrainFlow's playback board, and the bridge process end to end over Zenoh."""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from sctd.wire import DEFAULT_ROBOT, Keys, codec
from sctd.wire.session import close_session, open_session
from sctd_services.input.device import InputError
from sctd_services.input.emg import Emg
from sctd_services.input.emg.board import write_playback
from sctd_services.input.emg.calibration import PHASES, fit, load, save
from sctd_services.input.emg.device import Processor
from sctd_services.input.emg.processing import AxisMap, Chain, Filters, fit_axis_map, group_delay_s
from sctd_services.input.emg.synthetic import contractions
from tests.conftest import ROOT, Proc, free_port, wait_for

FS = 250.0  # BrainFlow's synthetic board, whose row layout the playback files use
CHANNELS = list(range(1, 9))
PHASE_S, SETTLE_S = 2.0, 0.5
AXIS = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def _args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    Emg().add_arguments(p.add_argument_group("emg"))
    return p.parse_args(list(argv))


# --- the chain on arrays ---------------------------------------------------------------

def test_band_top_stays_below_the_nyquist_limit():
    assert Filters().band_hz(250.0) == (20.0, 112.5)
    assert Filters().band_hz(2000.0) == (20.0, 450.0)
    with pytest.raises(ValueError, match="Nyquist"):
        Filters(band_high_hz=200.0).band_hz(250.0)


@pytest.mark.parametrize(("f_hz", "lo", "hi"), [(60.0, 0.65, 0.75), (5.0, 0.0, 0.05), (124.0, 0.0, 0.2)])
def test_bandpass_passes_a_sine_in_the_band_and_stops_one_outside(f_hz, lo, hi):
    t = np.arange(int(4 * FS)) / FS
    x = np.sin(2 * np.pi * f_hz * t)[:, None]
    y = Chain(Filters(), FS, 1).bandpass(x)[int(FS):]  # past the transient
    assert lo <= _rms(y) <= hi


def test_chunks_of_any_size_give_the_whole_signal_s_envelope():
    rng = np.random.default_rng(3)
    x = rng.standard_normal((1000, 4))
    whole = Chain(Filters(), FS, 4).envelope(x)
    chain = Chain(Filters(), FS, 4)
    cuts = np.cumsum(rng.integers(0, 7, size=400))
    parts = [chain.envelope(c) for c in np.split(x, cuts[cuts < len(x)])]
    np.testing.assert_allclose(np.vstack(parts), whole, atol=1e-12)


def test_envelope_of_a_burst_settles_at_its_rectified_mean():
    t = np.arange(int(4 * FS)) / FS
    amplitude = 80.0
    x = np.where(t >= 1.0, amplitude * np.sin(2 * np.pi * 70.0 * t), 0.0)[:, None]
    env = Chain(Filters(), FS, 1).envelope(x)[:, 0]
    assert np.all(np.abs(env[: int(FS)]) < 1e-9)  # causal: nothing before the burst
    held = env[int(2.5 * FS):]
    assert abs(held.mean() - 2 * amplitude / np.pi) < 0.05 * 2 * amplitude / np.pi


def test_envelope_group_delay_is_the_butterworth_s():
    for fc in (3.0, 4.0, 5.0):
        chain = Chain(Filters(envelope_hz=fc), FS, 1)
        assert chain.envelope_delay_s == pytest.approx(np.sqrt(2) / (2 * np.pi * fc), rel=0.03)
        assert group_delay_s(chain.env_sos, FS) == chain.envelope_delay_s


@pytest.mark.parametrize("seed", range(5))
def test_ridge_fit_recovers_planted_axes(seed):
    rng = np.random.default_rng(seed)
    W, b = rng.normal(size=(6, 3)), rng.normal(size=3) * 0.1
    A = rng.uniform(0, 1, size=(2000, 6))
    m = fit_axis_map(A, A @ W + b, ridge=1e-6, deadzone=0.0)
    np.testing.assert_allclose(m.matrix, W, atol=1e-3)
    np.testing.assert_allclose(m.bias, b, atol=1e-3)


def test_axis_map_dead_zone_and_co_contraction_rule():
    m = AxisMap(matrix=np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 0, 0]]), bias=np.zeros(3),
                deadzone=0.1, cocontraction=0.5)
    assert m(np.array([0.05, 0.0, 0.9]))[0] == 0.0  # inside the dead zone
    assert m(np.array([0.55, 0.0, 0.0]))[0] == pytest.approx(0.5)  # rescaled from its edge
    assert m(np.array([0.9, 0.1, 0.0]))[0] == pytest.approx((0.8 - 0.1) / 0.9)
    # both used channels active: zero; channel 2 has no row, so it does not count
    assert np.all(m(np.array([1.0, 0.6, 0.0])) == 0.0)


def _envelopes(seed: int) -> dict[str, np.ndarray]:
    x = contractions([(p.name, PHASE_S) for p in PHASES], FS, len(CHANNELS), seed)
    env = Chain(Filters(), FS, len(CHANNELS)).envelope(x)
    n = round(PHASE_S * FS)
    return {p.name: env[i * n:(i + 1) * n] for i, p in enumerate(PHASES)}


def _phase_means(cal, seed: int) -> dict[str, np.ndarray]:
    """Each phase's mean axes through the calibrated chain, on a fresh recording."""
    x = contractions([(p.name, PHASE_S) for p in PHASES], FS, len(cal.channels), seed)
    proc, n, skip = Processor(cal), round(PHASE_S * FS), round(SETTLE_S * FS)
    u = np.array([proc(x[i:i + 3]).copy() for i in range(0, len(x), 3)])  # 3-sample chunks
    return {p.name: u[(k * n + skip) // 3:((k + 1) * n) // 3].mean(axis=0) for k, p in enumerate(PHASES)}


def _assert_each_contraction_on_its_axis(means: dict[str, np.ndarray]):
    for name, u in means.items():
        if name in AXIS:
            axis, sign = AXIS[name]
            assert sign * u[axis] > 0.5, f"{name}: u {u}"
            assert np.all(np.abs(np.delete(u, axis)) < 0.2), f"{name}: u {u}"
        else:
            assert np.all(np.abs(u) < 0.1), f"{name}: u {u}"


@pytest.mark.parametrize("seed", range(6))
def test_calibration_fit_maps_fresh_synthetic_contractions_to_their_axes(seed):
    cal = fit(_envelopes(seed), board="synthetic", channels=CHANNELS, rate_hz=FS, filters=Filters(),
              settle_s=SETTLE_S)
    _assert_each_contraction_on_its_axis(_phase_means(cal, 100 + seed))


def test_calibration_file_round_trips_and_names_a_bad_field(tmp_path):
    cal = fit(_envelopes(1), board="synthetic", channels=CHANNELS, rate_hz=FS, filters=Filters(),
              settle_s=SETTLE_S)
    path = tmp_path / "cal.json"
    save(cal, path)
    back = load(path)
    np.testing.assert_array_equal(back.mapping.matrix, cal.mapping.matrix)
    np.testing.assert_array_equal(back.normalisation.mvc, cal.normalisation.mvc)
    assert (back.channels, back.rate_hz, back.filters) == (cal.channels, cal.rate_hz, cal.filters)
    obj = json.loads(path.read_text())
    assert {"version", "board", "channels", "rate_hz", "filters", "normalisation", "mapping",
            "created"} <= obj.keys()
    obj["mapping"]["matrix"] = obj["mapping"]["matrix"][:3]
    path.write_text(json.dumps(obj))
    with pytest.raises(InputError, match=r"cal\.json.*mapping\.matrix: shape"):
        load(path)


# --- through BrainFlow -----------------------------------------------------------------

def _sockets() -> int:
    n = 0
    for fd in os.listdir("/proc/self/fd"):
        try:
            n += os.readlink(f"/proc/self/fd/{fd}").startswith("socket:")
        except OSError:
            pass
    return n


@pytest.fixture(scope="module")
def calibration(tmp_path_factory):
    """A calibration written by ``--calibrate`` (the real CLI, stdin not a terminal) from
    a playback file of synthetic contractions whose phases follow its timeline."""
    folder = tmp_path_factory.mktemp("emg")
    rec, out = folder / "calibrate.csv", folder / "cal.json"
    x = contractions([(p.name, PHASE_S) for p in PHASES] + [("rest", 1.0)], FS, len(CHANNELS), 11)
    write_playback(str(rec), x, CHANNELS, FS)
    r = subprocess.run([sys.executable, "-m", "sctd_services.input", "emg", "--calibrate",
                        "--board", "playback", "--board-file", str(rec), "--calibration", str(out),
                        "--phase-seconds", str(PHASE_S), "--settle-seconds", str(SETTLE_S)],
                       stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=90, cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    return out, r.stdout


@pytest.mark.slow
def test_calibrate_through_the_playback_board_maps_each_contraction_to_its_axis(calibration):
    path, said = calibration
    for p in PHASES:
        assert f"{p.name}: {p.say}" in said  # the guidance a person would read
    cal = load(path)
    assert cal.channels == CHANNELS and cal.rate_hz == FS
    assert cal.filters.band_hz(FS) == (20.0, 112.5)
    _assert_each_contraction_on_its_axis(_phase_means(cal, 12))


@pytest.mark.slow
def test_calibrate_refuses_to_overwrite_without_force(calibration):
    path, _ = calibration
    args = _args("--calibrate", "--board", "synthetic", "--calibration", str(path))
    with pytest.raises(InputError, match="exists; --force"):
        Emg().run_special(args)


@pytest.mark.slow
def test_synthetic_board_reads_within_range_and_opens_no_socket(calibration):
    path, _ = calibration
    before = _sockets()
    with Emg().open(None, _args("--board", "synthetic", "--calibration", str(path))) as dev:
        assert _sockets() == before  # no network, no multicast
        readings = []
        for _ in range(50):
            time.sleep(0.01)
            r = dev.read()
            assert r is not None
            readings.append(r.axes)
    u = np.array(readings)
    assert u.shape == (50, 3) and np.all(np.isfinite(u)) and np.all(np.abs(u) <= 1.0)


@pytest.mark.slow
def test_no_calibration_exits_1_saying_to_calibrate():
    r = subprocess.run([sys.executable, "-m", "sctd_services.input", "emg", "--board", "synthetic"],
                       stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=60, cwd=ROOT)
    assert r.returncode == 1
    assert "emg: no calibration" in r.stderr and "--calibrate" in r.stderr


@pytest.mark.slow
def test_bridge_publishes_the_file_s_contractions(calibration, tmp_path):
    path, _ = calibration
    timeline = [("rest", 3.0), ("+x", 2.0), ("rest", 1.5), ("-y", 2.0), ("rest", 1.5),
                ("co-contract", 2.0), ("rest", 1.0)]
    rec = tmp_path / "drive.csv"
    write_playback(str(rec), contractions(timeline, FS, len(CHANNELS), 21), CHANNELS, FS)
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    got: list[tuple[float, ...]] = []
    stamps: list[float] = []
    lock = threading.Lock()

    def on_sample(sample):
        msg = codec.decode_input(bytes(sample.payload.to_bytes()))
        with lock:
            got.append(msg.u)
            stamps.append(msg.stamp)

    s = open_session(listen=[ep])
    try:
        sub = s.declare_subscriber(Keys(DEFAULT_ROBOT).input("emg"), on_sample)
        log = tmp_path / "bridge.log"
        with Proc("sctd_services.input", "emg", "--board", "playback", "--board-file", str(rec),
                  "--calibration", str(path), "--connect", ep, log=log) as bridge:
            assert wait_for(lambda: "disconnected" in log.read_text(), timeout=40), log.read_text()
            time.sleep(0.3)
            assert bridge.stop() == 0, log.read_text()
        sub.undeclare()
    finally:
        close_session(s)
    u, t = np.array(got), np.array(stamps)

    def span(idx: np.ndarray) -> float:
        """Seconds the messages ``idx`` cover, by the bridge's stamps (a loaded machine
        publishes fewer messages, each with the newest envelope, over the same time)."""
        return float(t[idx[-1]] - t[idx[0]]) if len(idx) > 10 else 0.0

    plus_x = np.flatnonzero((u[:, 0] > 0.5) & (np.abs(u[:, 1]) < 0.2) & (np.abs(u[:, 2]) < 0.2))
    minus_y = np.flatnonzero((u[:, 1] < -0.5) & (np.abs(u[:, 0]) < 0.2) & (np.abs(u[:, 2]) < 0.2))
    # 2 s contractions, less the envelope's rise and fall
    assert span(plus_x) > 1.0 and span(minus_y) > 1.0, f"+x {span(plus_x)} s, -y {span(minus_y)} s"
    assert plus_x[-1] < minus_y[0]  # in the file's order
    # rest, co-contraction, rest: 4.5 s of the file, then disconnected
    after = np.arange(np.flatnonzero(u[:, 1] < -0.2)[-1] + 1, len(u))
    assert span(after) > 3.5 and np.all(np.abs(u[after]) < 0.2), np.abs(u[after]).max(axis=0)
    assert np.all(u[-3:] == 0.0)  # zero on exit


def test_a_dip_in_a_held_co_contraction_keeps_the_axes_at_zero():
    cal = fit(_envelopes(1), board="synthetic", channels=CHANNELS, rate_hz=FS, filters=Filters(),
              settle_s=SETTLE_S)
    assert cal.mapping.cocontraction is not None
    assert not [n for n in cal.notes if n.startswith("phase")], cal.notes
    x = contractions([("co-contract", 3.0), ("rest", 2.0)], FS, len(CHANNELS), 5)
    x[round(1.5 * FS):round(1.6 * FS), 1] *= 0.05  # channel 2 (-x) drops out for 0.1 s
    proc = Processor(cal)
    u = np.array([proc(x[i:i + 2]).copy() for i in range(0, len(x), 2)])
    assert np.all(u[round(0.5 * FS) // 2:] == 0.0)
    # without the hold the dip moves +x: the rule alone is not what keeps it at zero
    a = cal.normalisation(Chain(cal.filters, FS, len(CHANNELS)).envelope(x))
    assert cal.mapping(a)[:, 0].max() > 0.3


@pytest.mark.slow
def test_open_refuses_other_channels_and_streaming_boards(calibration):
    path, _ = calibration
    with pytest.raises(InputError, match=r"--channels 1,2 differ from the calibration's"):
        Emg().open(None, _args("--calibration", str(path), "--channels", "1,2"))
    with pytest.raises(InputError, match="streaming boards open network sockets"):
        Emg().open(None, _args("--calibration", str(path), "--board", "STREAMING_BOARD"))


@pytest.mark.slow
def test_ctrl_c_ends_the_calibration_without_writing(tmp_path):
    rec, out = tmp_path / "long.csv", tmp_path / "cal.json"
    write_playback(str(rec), contractions([("rest", 60.0)], FS, len(CHANNELS), 4), CHANNELS, FS)
    p = subprocess.Popen([sys.executable, "-m", "sctd_services.input", "emg", "--calibrate",
                          "--board", "playback", "--board-file", str(rec), "--calibration", str(out)],
                         stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, cwd=ROOT, start_new_session=True)
    try:
        assert wait_for(lambda: p.stdout is not None and "[1/8] rest" in p.stdout.readline(), timeout=30)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=20)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130, err
    assert "interrupted" in err and not out.exists()


@pytest.mark.parametrize("arrives_as", ["KeyboardInterrupt", "ctypes.ArgumentError"])
def test_ctrl_c_anywhere_in_the_calibration_is_an_interruption(arrives_as, tmp_path, monkeypatch, capsys):
    """Ctrl-C raised inside a ctypes call into BrainFlow reaches Python as a
    ctypes.ArgumentError (seen on a loaded machine): still an interruption, exit 130,
    nothing written; an ArgumentError without a Ctrl-C stays an error."""
    import argparse
    import ctypes

    from sctd_services.input import add_arguments
    from sctd_services.input.emg import Emg

    def calibrate(self, args, path, filters):
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt as e:
            if arrives_as == "KeyboardInterrupt":
                raise
            raise ctypes.ArgumentError("argument 2: KeyboardInterrupt: ") from e

    p = argparse.ArgumentParser()
    add_arguments(p)
    out = tmp_path / "cal.json"
    args = p.parse_args(["emg", "--calibrate", "--board", "synthetic", "--calibration", str(out)])
    monkeypatch.setattr(Emg, "_calibrate", calibrate)
    before = signal.getsignal(signal.SIGINT)
    assert Emg().run_special(args) == 130 and not out.exists()
    assert "interrupted" in capsys.readouterr().err
    assert signal.getsignal(signal.SIGINT) is before  # the handlers were put back

    def broken(self, args, path, filters):
        raise ctypes.ArgumentError("argument 1: a real bug")

    monkeypatch.setattr(Emg, "_calibrate", broken)
    with pytest.raises(ctypes.ArgumentError, match="a real bug"):
        Emg().run_special(args)
