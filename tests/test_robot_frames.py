"""The motor command frame, over real UDP sockets on 127.0.0.1 and a pseudo-terminal."""

from __future__ import annotations

import os
import time
import tty

import pytest
from hypothesis import given
from hypothesis import strategies as st

from roachplan.robot import (
    FRAME_SIZE,
    CommandFrame,
    FdCommandReceiver,
    FrameReader,
    RobotError,
    SerialCommandLink,
    SerialLinkSettings,
    UdpCommandLink,
    UdpCommandReceiver,
    UdpLinkSettings,
    decode_command,
    encode_command,
)

speeds = st.floats(min_value=-60.0, max_value=60.0, width=32)


@given(seq=st.integers(0, 2**32 - 1), t_us=st.integers(0, 2**64 - 1), left=speeds, right=speeds)
def test_a_frame_round_trips_exactly(seq, t_us, left, right):
    frame = CommandFrame(seq=seq, t_us=t_us, left=left, right=right)
    data = encode_command(frame)
    assert len(data) == FRAME_SIZE == 28
    assert data[:3] == b"RC\x01"
    assert decode_command(data) == frame


def test_a_stop_frame_round_trips_and_a_corrupted_one_is_refused():
    stop = CommandFrame(seq=7, t_us=1, left=0.0, right=0.0, stop=True)
    data = bytearray(encode_command(stop))
    assert decode_command(bytes(data)) == stop
    data[17] ^= 0x40
    with pytest.raises(RobotError, match="CRC"):
        decode_command(bytes(data))
    with pytest.raises(RobotError, match="stop frame"):
        encode_command(CommandFrame(seq=1, t_us=1, left=1.0, right=0.0, stop=True))


def test_the_stream_reader_resynchronises_after_noise_and_a_cut_frame():
    frames = [CommandFrame(seq=k, t_us=k, left=float(k), right=-float(k)) for k in range(4)]
    data = [encode_command(f) for f in frames]
    stream = b"\x00RC\x01junk" + data[0] + data[1][:10] + data[2] + b"R" + data[3]
    reader = FrameReader()
    got = []
    for i in range(0, len(stream), 5):  # as a serial line delivers it: a few bytes at a time
        got += reader.feed(stream[i : i + 5])
    assert [f.seq for f in got] == [0, 2, 3]
    assert reader.skipped > 0


def test_udp_commands_reach_a_receiver_on_loopback():
    receiver = UdpCommandReceiver("127.0.0.1", 0)
    link = UdpCommandLink(UdpLinkSettings(host="127.0.0.1", port=receiver.port))
    try:
        sent = [link.send(10.0, 12.5), link.send(0.0, 0.0, stop=True)]
        got: list[CommandFrame] = []
        deadline = time.monotonic() + 5
        while len(got) < 2 and time.monotonic() < deadline:
            got += receiver.poll()
            time.sleep(0.01)
        assert got == sent
        assert [f.seq for f in got] == [0, 1] and got[1].stop
    finally:
        link.close()
        receiver.close()


def test_serial_commands_reach_the_other_end_of_a_pseudo_terminal():
    master, slave = os.openpty()
    tty.setraw(slave)
    receiver = FdCommandReceiver(master)
    link = SerialCommandLink(SerialLinkSettings(port=os.ttyname(slave)))
    try:
        sent = [link.send(20.0, 18.0), link.send(-5.0, 5.0), link.send(0, 0, stop=True)]
        got: list[CommandFrame] = []
        deadline = time.monotonic() + 5
        while len(got) < 3 and time.monotonic() < deadline:
            got += receiver.poll()
            time.sleep(0.01)
        assert got == sent
    finally:
        link.close()
        receiver.close()
        os.close(slave)


def test_a_serial_device_that_is_not_there_is_named_in_the_error():
    with pytest.raises(RobotError, match="/dev/nonexistent-bridge"):
        SerialCommandLink(SerialLinkSettings(port="/dev/nonexistent-bridge"))
