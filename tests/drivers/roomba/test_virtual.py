"""The virtual Roomba, spoken to byte by byte over a real pseudo-terminal with pyserial.

These tests use no driver: they check the emulator against the Open
Interface rules of the spec (§2 modes, §3 commands, §4 sensor access, §8.5
emulator checklist; sections as listed in :mod:`drivers.roomba.oi`).
"""

from __future__ import annotations

import dataclasses
import struct
import time

import numpy as np
import pytest
import serial

from drivers.roomba import oi
from drivers.roomba.oi import OIMode, Opcode, StreamParser
from drivers.roomba.virtual import DEFAULT_BANNER, VirtualRoomba, serve
from drivers.roomba.virtual_options import VirtualRoombaOptions

SPEED = 10.0


@pytest.fixture
def vr():
    with VirtualRoomba(seed=7, options=VirtualRoombaOptions(speed=SPEED)) as robot:
        yield robot


@pytest.fixture
def port(vr):
    with serial.Serial(vr.device_path, 115200, timeout=0.02, write_timeout=0.5,
                       exclusive=True) as ser:
        yield ser


def read_exactly(ser: serial.Serial, n: int, *, timeout_s: float = 2.0) -> bytes:
    """Read ``n`` bytes or fail after ``timeout_s``."""
    out = b""
    deadline = time.monotonic() + timeout_s
    while len(out) < n and time.monotonic() < deadline:
        out += ser.read(n - len(out))
    assert len(out) == n, f"expected {n} bytes, got {len(out)}: {out!r}"
    return out


def query(ser: serial.Serial, ids: list[int]) -> dict[int, int]:
    """Query List (149) with flushed input and an exact-length read (spec §4)."""
    ser.reset_input_buffer()
    ser.write(oi.query_list(ids))
    return oi.decode_query_list_reply(ids, read_exactly(ser, oi.query_reply_size(ids)))


def wait_periods(vr: VirtualRoomba, n: int) -> None:
    """Let the emulator run ``n`` more periods."""
    target = vr.stats.periods + n
    assert vr.wait_until(lambda r: r.stats.periods >= target, timeout_s=5.0)


def collect_frames(ser: serial.Serial, parser: StreamParser, *, duration_s: float) -> list:
    """Parse everything that arrives during ``duration_s`` of wall time."""
    frames = []
    deadline = time.monotonic() + duration_s
    while time.monotonic() < deadline:
        frames += parser.feed(ser.read(max(1, ser.in_waiting)))
    return frames


def test_starts_in_off_and_listens_only_for_start(vr, port):
    # none of these bytes is Start (128) or Reset (7): Off ignores them all (spec §2)
    junk = oi.drive_direct(100, 100) + oi.safe() + oi.stream([43])
    port.write(junk)
    assert vr.wait_until(lambda r: r.stats.bytes_ignored == len(junk))
    assert vr.received == []
    port.write(oi.start())
    assert query(port, [35]) == {35: OIMode.PASSIVE}
    port.write(oi.safe())
    assert query(port, [35]) == {35: OIMode.SAFE}
    port.write(oi.full())
    assert query(port, [35]) == {35: OIMode.FULL}
    assert [c.opcode for c in vr.received][:2] == [Opcode.START, Opcode.QUERY_LIST]


def test_drive_direct_only_in_safe_or_full_right_wheel_first(vr, port):
    port.write(oi.start() + oi.drive_direct(left_mm_s=120, right_mm_s=-80))
    assert vr.wait_until(lambda r: any(c.opcode == Opcode.DRIVE_DIRECT for c in r.received))
    passive = next(c for c in vr.received if c.opcode == Opcode.DRIVE_DIRECT)
    assert not passive.accepted and passive.mode == OIMode.PASSIVE
    assert query(port, [41, 42]) == {41: 0, 42: 0}
    port.write(oi.safe() + oi.drive_direct(left_mm_s=120, right_mm_s=-80))
    assert query(port, [41, 42]) == {41: -80, 42: 120}     # 41 right, 42 left (spec §5)
    wait_periods(vr, 3)
    assert np.allclose(vr.applied_commands_m_s[-1], [0.120, -0.080])


def test_partial_command_waits_for_its_data_bytes(vr, port):
    port.write(oi.start() + oi.safe())
    cmd = oi.drive_direct(left_mm_s=50, right_mm_s=100)
    port.write(cmd[:2])
    wait_periods(vr, 3)
    assert Opcode.DRIVE_DIRECT not in [c.opcode for c in vr.received]
    port.write(cmd[2:])
    assert query(port, [41, 42]) == {41: 100, 42: 50}


def test_one_missing_byte_swallows_the_next_opcode(vr, port):
    port.write(oi.start() + oi.safe())
    port.write(oi.drive_direct(left_mm_s=0, right_mm_s=100)[:4] + oi.start())
    assert vr.wait_until(lambda r: any(c.opcode == Opcode.DRIVE_DIRECT for c in r.received))
    drive = [c for c in vr.received if c.opcode == Opcode.DRIVE_DIRECT][-1]
    assert drive.data == bytes([0, 100, 0, Opcode.START])   # Start became a data byte (§2)
    assert query(port, [35]) == {35: OIMode.SAFE}


def test_unknown_opcodes_are_ignored(vr, port):
    port.write(oi.start())
    port.write(bytes([0, 1, 200, 255]))
    assert query(port, [35]) == {35: OIMode.PASSIVE}
    assert vr.stats.bytes_ignored == 4


def test_drive_137_kinematics(vr, port):
    port.write(oi.start() + oi.full())
    port.write(struct.pack(">Bhh", Opcode.DRIVE, 200, -1))      # spin clockwise (spec §3.1)
    assert query(port, [41, 42]) == {41: -200, 42: 200}
    port.write(struct.pack(">Bhh", Opcode.DRIVE, 200, -32768))  # straight
    assert query(port, [41, 42]) == {41: 200, 42: 200}


def test_stream_pause_resume_and_stop(vr, port):
    ids = [7, 35, 43, 44]
    parser = StreamParser(ids)
    port.write(oi.start() + oi.safe() + oi.stream(ids))
    frames = collect_frames(port, parser, duration_s=0.1)
    assert len(frames) >= 3 and all(f[35] == OIMode.SAFE for f in frames)
    assert parser.checksum_failures == 0 and parser.bytes_dropped == 0
    port.write(oi.pause_resume_stream(resume=False))
    assert vr.wait_until(lambda r: r.received[-1].opcode == Opcode.PAUSE_RESUME_STREAM)
    sent = vr.stats.frames_sent
    wait_periods(vr, 5)
    assert vr.stats.frames_sent == sent
    port.write(oi.pause_resume_stream(resume=True))
    wait_periods(vr, 5)
    assert vr.stats.frames_sent > sent
    port.write(oi.stop())
    assert vr.wait_until(lambda r: r.received[-1].opcode == Opcode.STOP)
    sent = vr.stats.frames_sent
    wait_periods(vr, 5)
    assert vr.stats.frames_sent == sent
    assert vr.mode == OIMode.OFF


def test_sensors_142_replies_bare_data_bytes(vr, port):
    port.write(oi.start())
    port.reset_input_buffer()
    port.write(oi.sensors(106))                     # group 106: light bumps 46-51, 12 bytes
    values = oi.decode_query_list_reply([106], read_exactly(port, 12))
    assert sorted(values) == [46, 47, 48, 49, 50, 51]
    assert all(0 <= v <= 4095 for v in values.values())


def test_reset_prints_the_banner_and_ends_in_off(vr, port):
    port.write(oi.start() + oi.safe())
    port.reset_input_buffer()
    port.write(oi.reset())
    assert read_exactly(port, len(DEFAULT_BANNER)).decode("ascii") == DEFAULT_BANNER
    assert vr.wait_until(lambda r: r.mode == OIMode.OFF)
    port.write(oi.sensors(35))                      # ignored in Off: no reply
    assert port.read(1) == b""


def test_encoders_count_in_the_commanded_direction(vr, port):
    port.write(oi.start() + oi.full() + oi.drive_direct(-200, -200))
    wait_periods(vr, 20)
    ticks = query(port, [43, 44])
    assert ticks[43] > 60000 and ticks[44] > 60000   # 0 minus a few ticks wraps (spec §7)


def test_wheel_drop_forces_passive_and_stops_the_motors():
    with VirtualRoomba(seed=3,
                       options=VirtualRoombaOptions(speed=SPEED, passive_at_s=0.3,
                                                    passive_duration_s=10.0)) as vr, \
            serial.Serial(vr.device_path, 115200, timeout=0.02, exclusive=True) as port:
        port.write(oi.start() + oi.safe() + oi.drive_direct(100, 100))
        assert vr.wait_until(lambda r: r.sim.t_s > 0.35, timeout_s=3.0)
        assert query(port, [35, 7]) == {35: OIMode.PASSIVE, 7: 0b1100}
        port.write(oi.safe() + oi.drive_direct(100, 100))   # Safe falls back again
        wait_periods(vr, 3)
        assert query(port, [35]) == {35: OIMode.PASSIVE}
        assert np.all(vr.applied_commands_m_s[-3:] == 0.0)


def test_line_faults_corrupt_and_drop_outgoing_bytes():
    with VirtualRoomba(seed=11,
                       options=VirtualRoombaOptions(speed=SPEED, corrupt_probability=0.05,
                                                    drop_probability=0.02)) as vr, \
            serial.Serial(vr.device_path, 115200, timeout=0.02, exclusive=True) as port:
        parser = StreamParser([43, 44])
        port.write(oi.start() + oi.stream([43, 44]))
        deadline = time.monotonic() + 10.0
        while vr.stats.frames_sent < 300 and time.monotonic() < deadline:   # 2700 bytes
            parser.feed(port.read(max(1, port.in_waiting)))
        stats = vr.stats
    n = stats.bytes_sent + stats.bytes_dropped
    assert n > 1000
    assert 0.02 < stats.bytes_corrupted / n < 0.09        # binomial, 5 %
    assert 0.005 < stats.bytes_dropped / n < 0.04         # binomial, 2 %
    assert parser.checksum_failures + parser.bad_length > 0
    assert parser.frames_ok < stats.frames_sent


def test_charger_text_at_a_given_time():
    text = "bat: min 1 sec 2\r\n"
    with VirtualRoomba(seed=1,
                       options=VirtualRoombaOptions(speed=SPEED, charger_text_at_s=0.2,
                                                    charger_text=text)) as vr, \
            serial.Serial(vr.device_path, 115200, timeout=0.02, exclusive=True) as port:
        port.write(oi.start())
        assert read_exactly(port, len(text), timeout_s=3.0) == text.encode()


def test_options_are_validated():
    with pytest.raises(ValueError, match="speed"):
        VirtualRoomba(options=VirtualRoombaOptions(speed=0.0))
    with pytest.raises(ValueError, match="corrupt_probability"):
        VirtualRoomba(options=VirtualRoombaOptions(corrupt_probability=1.5))
    with pytest.raises(ValueError, match="stall_duration_s"):
        VirtualRoomba(options=VirtualRoombaOptions(stall_duration_s=0.0))
    options = VirtualRoombaOptions(speed=4.0, mode_report_offset=1)
    vr = VirtualRoomba(seed=2, options=options)
    assert vr.options is options and vr.speed == 4.0 and vr.seed == 2
    with pytest.raises(dataclasses.FrozenInstanceError):
        options.speed = 1.0
    with pytest.raises(TypeError):
        VirtualRoombaOptions(2.0)                               # keyword-only
    with pytest.raises(ValueError, match="options must be a VirtualRoombaOptions, got dict"):
        VirtualRoomba(options={"speed": 4.0})


def test_start_and_stop_are_idempotent_and_quick():
    vr = VirtualRoomba(seed=0, options=VirtualRoombaOptions(speed=SPEED))
    t0 = time.monotonic()
    vr.start()
    path = vr.device_path
    assert vr.start().device_path == path and vr.running
    vr.stop()
    vr.stop()
    assert not vr.running and vr.error is None
    assert time.monotonic() - t0 < 5.0


def test_serve_prints_how_to_connect():
    out: list[str] = []
    stats = serve(seed=2, speed=SPEED, print_fn=out.append, duration_s=0.1)
    assert "/dev/" in out[0] and "Roomba(" in out[1]
    assert stats.periods > 0 and "stopped" in out[-1]
