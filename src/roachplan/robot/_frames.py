"""The motor command frame: what roachplan sends a robot, over UDP or a serial line.

One frame is 28 bytes, little-endian:

    offset  size  field
    0       2     magic, the bytes "RC" (0x52 0x43)
    2       1     version, 1
    3       1     flags: bit 0 STOP (the robot is to stand still: both speeds are 0); bits 1-7 0
    4       4     seq, uint32: +1 each frame a sender sends (wraps at 2^32)
    8       8     t_us, uint64: the sender's monotonic clock when the frame was made [us]
    16      4     left, float32: left motor speed [rad/s], positive walks forward
    20      4     right, float32: right motor speed [rad/s]
    24      4     crc, uint32: CRC-32 (IEEE 802.3, zlib's crc32) of bytes 0-23

Over UDP one datagram holds one frame. On a serial line (a radio bridge) frames follow each
other with nothing between them; a receiver finds a frame by its magic and keeps it only when
its CRC matches, else drops one byte and looks again (FrameReader), so a line that starts
mid-frame or loses bytes resynchronises within one frame. A robot should stop by itself when
no valid frame has come for a while (the twin: 0.25 s), as the sender may be gone.
"""

from __future__ import annotations

import math
import struct
import zlib
from dataclasses import dataclass

from ._errors import RobotError

MAGIC = b"RC"
VERSION = 1
FLAG_STOP = 0x01
_BODY = struct.Struct("<2sBBIQff")
_CRC = struct.Struct("<I")
FRAME_SIZE = _BODY.size + _CRC.size
"""Bytes in one frame (28)."""


@dataclass(frozen=True, kw_only=True)
class CommandFrame:
    """One motor command."""

    seq: int
    """Sequence number, uint32."""
    t_us: int
    """The sender's monotonic clock when it made the frame [us]."""
    left: float
    """Left motor speed [rad/s]."""
    right: float
    """Right motor speed [rad/s]."""
    stop: bool = False
    """The robot is to stand still (left and right are then 0)."""


def encode_command(frame: CommandFrame) -> bytes:
    """The 28 bytes of a frame; RobotError for a speed that is not finite or a stop frame
    with speeds, a seq or t_us out of range."""
    if not (math.isfinite(frame.left) and math.isfinite(frame.right)):
        raise RobotError(
            f"command seq {frame.seq}: motor speeds must be finite, got {frame.left}, {frame.right}"
        )
    if frame.stop and (frame.left != 0.0 or frame.right != 0.0):
        raise RobotError(f"command seq {frame.seq}: a stop frame has speeds 0, got nonzero")
    if not 0 <= frame.seq < 2**32 or not 0 <= frame.t_us < 2**64:
        raise RobotError(
            f"command: seq must be 0..2^32-1 and t_us 0..2^64-1, got {frame.seq}, {frame.t_us}"
        )
    body = _BODY.pack(
        MAGIC,
        VERSION,
        FLAG_STOP if frame.stop else 0,
        frame.seq,
        frame.t_us,
        frame.left,
        frame.right,
    )
    return body + _CRC.pack(zlib.crc32(body))


def decode_command(data: bytes) -> CommandFrame:
    """A frame from exactly FRAME_SIZE bytes; RobotError naming what is wrong (length, magic,
    version, CRC, flags)."""
    if len(data) != FRAME_SIZE:
        raise RobotError(f"command frame: expected {FRAME_SIZE} bytes, got {len(data)}")
    body = bytes(data[: _BODY.size])
    (crc,) = _CRC.unpack_from(data, _BODY.size)
    magic, version, flags, seq, t_us, left, right = _BODY.unpack(body)
    if magic != MAGIC:
        raise RobotError(f"command frame: magic {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise RobotError(f"command frame: version {version}, this reader takes {VERSION}")
    if crc != zlib.crc32(body):
        raise RobotError(f"command frame seq {seq}: CRC mismatch (a corrupted frame)")
    if flags & ~FLAG_STOP:
        raise RobotError(f"command frame seq {seq}: unknown flags 0x{flags:02x}")
    return CommandFrame(seq=seq, t_us=t_us, left=left, right=right, stop=bool(flags & FLAG_STOP))


class FrameReader:
    """Frames out of a byte stream (a serial line): feed() what arrived, get the whole valid
    frames in it. Bytes that are no valid frame (noise, a cut frame) are skipped and counted."""

    def __init__(self) -> None:
        self._buf = bytearray()
        self.skipped = 0
        """Bytes dropped while looking for a valid frame."""

    def feed(self, data: bytes) -> list[CommandFrame]:
        self._buf += data
        frames: list[CommandFrame] = []
        while True:
            at = self._buf.find(MAGIC)
            if at < 0:  # keep a last byte that may be the first of a magic
                keep = 1 if self._buf[-1:] == MAGIC[:1] else 0
                self.skipped += len(self._buf) - keep
                del self._buf[: len(self._buf) - keep]
                return frames
            if at:
                self.skipped += at
                del self._buf[:at]
            if len(self._buf) < FRAME_SIZE:
                return frames
            try:
                frames.append(decode_command(bytes(self._buf[:FRAME_SIZE])))
            except RobotError:
                self.skipped += 1
                del self._buf[:1]
                continue
            del self._buf[:FRAME_SIZE]
