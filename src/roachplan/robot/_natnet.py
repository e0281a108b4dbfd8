"""OptiTrack NatNet: the robot's pose from Motive, and the twin's Motive-like server.

The client is the `natnet` package (0.3.0, pinned; MIT; Tim Schneider's python-natnet-client),
used in its unicast mode (`use_multicast=False`): it sends NAT_CONNECT from a command socket
bound to the local address to the server's command port (1510), and Motive then sends every
frame of data to that same socket, which the client keeps subscribed with NAT_KEEPALIVE
packets. Nothing joins a multicast group, so the whole exchange runs on 127.0.0.1 in tests.

The server side (NatNetServer, the packet builders) writes NatNet 4.1, what Motive 3.1 streams,
laid out as NaturalPoint's NatNet SDK 4.1 samples read it (PacketClient.cpp, NatNetClient.py):
every message is [message id uint16][payload size uint16][payload], little-endian, and

- NAT_SERVERINFO (1), the answer to NAT_CONNECT (0): sSender_Server, 279 bytes: the
  application's name (256 bytes, NUL-padded), its version and NatNet's (4 bytes each), the
  high-resolution clock's frequency (uint64), the data port (uint16), multicast (1 byte) and
  the multicast address (4 bytes).
- NAT_MODELDEF (5), the answer to NAT_REQUEST_MODELDEF (4): the number of data sets, then per
  set its type (1: a rigid body) and, from 4.1 on, its size in bytes; a rigid body's
  description is its name (NUL-terminated), id, parent id (-1), offset (3 float32), the
  number of markers, their offsets (3 float32 each), active labels (int32 each) and names.
- NAT_FRAMEOFDATA (7): the frame number; marker sets (a count and, from 4.1 on, a byte size
  before every list; each set a name, a count and positions), the legacy unlabelled markers,
  rigid bodies (id, position 3 float32 [m], orientation quaternion qx qy qz qw, mean marker
  error float32 [m], params int16 with bit 0 "tracking valid"), skeletons, assets (4.1),
  labelled markers (id, position, size, params int16, residual), force plates and devices,
  then the suffix: timecode and sub-timecode (uint32 each), the timestamp (float64 [s]), the
  camera mid-exposure, data-received and transmit stamps (uint64 each, in ticks of the
  high-resolution clock), the precision timestamp (seconds and fraction, uint32 each, 4.1),
  params (int16: bit 0 recording, bit 1 tracked models changed) and a 4-byte end-of-data tag.

What natnet 0.3.0 reads of it (tests/test_robot_natnet.py checks each against these packets):
the server info, the rigid body descriptions, and every field of a frame up to the suffix's
stamps, exactly. It does not know the 4.1 suffix's precision timestamp, so it reads the
frame's params (is_recording, tracked_models_changed) from that timestamp's first bytes:
roachplan uses neither. It reads uint64 stamps as the C long of the platform (8 bytes on
Linux and macOS, 4 on Windows, where the stamps after the first would be wrong): roachplan
takes the receive time from its own clock, not from the stamps.
"""

from __future__ import annotations

import math
import socket
import struct
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass

from roachplan._settings import check_settings, one_of, positive
from roachplan._settings import setting as s

from . import _checks
from ._errors import RobotError
from ._pose import PoseSample
from ._transform import quat_multiply

NAT_CONNECT = 0
NAT_SERVERINFO = 1
NAT_REQUEST = 2
NAT_RESPONSE = 3
NAT_REQUEST_MODELDEF = 4
NAT_MODELDEF = 5
NAT_FRAMEOFDATA = 7
NAT_KEEPALIVE = 10
NATNET_VERSION = (4, 1, 0, 0)
"""The NatNet version the server streams (Motive 3.1's)."""
MOTIVE_VERSION = (3, 1, 0, 0)
CLOCK_HZ = 10_000_000
"""Ticks per second of the server's high-resolution clock (the stamps in a frame's suffix)."""
DATASET_RIGID_BODY = 1


def _message(message_id: int, payload: bytes) -> bytes:
    if len(payload) > 0xFFFF:
        raise RobotError(f"NatNet message {message_id}: {len(payload)} bytes, at most 65535")
    return struct.pack("<HH", message_id, len(payload)) + payload


def _cstr(s: str) -> bytes:
    return s.encode("utf-8") + b"\0"


def _list(count: int, body: bytes) -> bytes:
    """A 4.1 list: its count, the size of its data in bytes, the data."""
    return struct.pack("<iI", count, len(body)) + body


def server_info_packet(
    *,
    application: str = "Motive",
    data_port: int = 1511,
    multicast_address: tuple[int, int, int, int] = (239, 255, 42, 99),
) -> bytes:
    """NAT_SERVERINFO as Motive 3.1 sends it in unicast mode (multicast flag 0)."""
    name = application.encode("utf-8")[:255].ljust(256, b"\0")
    payload = (
        name
        + bytes(MOTIVE_VERSION)
        + bytes(NATNET_VERSION)
        + struct.pack("<QHB", CLOCK_HZ, data_port, 0)
        + bytes(multicast_address)
    )
    return _message(NAT_SERVERINFO, payload)


@dataclass(frozen=True, kw_only=True)
class RigidBodyModel:
    """A rigid body as Motive describes it."""

    name: str
    id: int
    markers: tuple[tuple[float, float, float], ...] = ()
    """Marker offsets from the body's pivot [m], in the body's frame."""


def model_def_packet(bodies: Sequence[RigidBodyModel]) -> bytes:
    """NAT_MODELDEF describing the rigid bodies (NatNet 4.1)."""
    payload = struct.pack("<i", len(bodies))
    for b in bodies:
        n = len(b.markers)
        desc = (
            _cstr(b.name)
            + struct.pack("<ii3f", b.id, -1, 0.0, 0.0, 0.0)
            + struct.pack("<i", n)
            + b"".join(struct.pack("<3f", *m) for m in b.markers)
            + b"".join(struct.pack("<i", k + 1) for k in range(n))
            + b"".join(_cstr(f"Marker{k + 1}") for k in range(n))
        )
        payload += struct.pack("<iI", DATASET_RIGID_BODY, len(desc)) + desc
    return _message(NAT_MODELDEF, payload)


@dataclass(frozen=True, kw_only=True)
class RigidBodyFrame:
    """One rigid body in one frame of data."""

    id: int
    position: tuple[float, float, float]
    """[m], Motive's frame."""
    quat: tuple[float, float, float, float]
    """qx, qy, qz, qw."""
    error: float = 0.0002
    """Mean marker error [m]."""
    valid: bool = True
    """Tracking valid (params bit 0): Motive clears it when it lost the body."""


def frame_packet(
    frame_number: int,
    bodies: Sequence[RigidBodyFrame],
    *,
    timestamp: float,
    stamps: tuple[int, int, int] = (0, 0, 0),
    marker_sets: Sequence[tuple[str, Sequence[tuple[float, float, float]]]] = (),
) -> bytes:
    """NAT_FRAMEOFDATA (NatNet 4.1). timestamp: seconds since the stream started; stamps:
    (mid-exposure, data received, transmit) in CLOCK_HZ ticks; marker_sets: (name, marker
    positions [m]) each (Motive sends one per rigid body, and "all")."""
    sets = b"".join(
        _cstr(name) + struct.pack("<i", len(ms)) + b"".join(struct.pack("<3f", *m) for m in ms)
        for name, ms in marker_sets
    )
    rbs = b"".join(
        struct.pack("<i3f4ffh", b.id, *b.position, *b.quat, b.error, 1 if b.valid else 0)
        for b in bodies
    )
    secs = int(timestamp)
    frac = int((timestamp - secs) * 2**32) & 0xFFFFFFFF
    suffix = struct.pack("<IId3QIIhi", 0, 0, timestamp, *stamps, secs, frac, 0, 0)
    payload = (
        struct.pack("<i", frame_number)
        + _list(len(marker_sets), sets)
        + _list(0, b"")  # legacy unlabelled markers
        + _list(len(bodies), rbs)
        + _list(0, b"")  # skeletons
        + _list(0, b"")  # assets (4.1)
        + _list(0, b"")  # labelled markers
        + _list(0, b"")  # force plates
        + _list(0, b"")  # devices
        + suffix
    )
    return _message(NAT_FRAMEOFDATA, payload)


class NatNetServer:
    """A Motive-like NatNet server in unicast mode: answers NAT_CONNECT and
    NAT_REQUEST_MODELDEF on its command port, and sends frames (publish) to every client that
    connected or sent a keep-alive in the last `subscription` seconds. Bound to host (only
    127.0.0.1 in tests); port 0 picks a free port. Not thread-safe: one thread calls serve()
    and publish()."""

    def __init__(
        self,
        bodies: Sequence[RigidBodyModel],
        *,
        host: str = "127.0.0.1",
        port: int = 0,
        subscription: float = 5.0,
    ) -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, port))
        self._sock.setblocking(False)
        self.port = self._sock.getsockname()[1]
        self._model = model_def_packet(bodies)
        self._info = server_info_packet()
        self._clients: dict[tuple[str, int], float] = {}
        self.subscription = subscription

    def fileno(self) -> int:
        return self._sock.fileno()

    @property
    def clients(self) -> int:
        return len(self._clients)

    def serve(self, now: float | None = None) -> None:
        """Answer every request that has arrived (none waits)."""
        now = time.monotonic() if now is None else now
        while True:
            try:
                data, addr = self._sock.recvfrom(4096)
            except BlockingIOError:
                break
            except ConnectionResetError:  # an ICMP error of an earlier frame to a gone client
                continue
            if len(data) < 4:
                continue
            (message_id,) = struct.unpack_from("<H", data)
            if message_id == NAT_CONNECT:
                self._clients[addr] = now
                self._send(self._info, addr)
            elif message_id == NAT_KEEPALIVE:
                self._clients[addr] = now
            elif message_id == NAT_REQUEST_MODELDEF:
                self._send(self._model, addr)
            elif message_id == NAT_REQUEST:
                self._send(_message(NAT_RESPONSE, struct.pack("<i", 0)), addr)
        for addr, seen in list(self._clients.items()):
            if now - seen > self.subscription:
                del self._clients[addr]

    def publish(self, packet: bytes) -> None:
        """Send a frame of data to every subscribed client."""
        for addr in list(self._clients):
            self._send(packet, addr)

    def _send(self, packet: bytes, addr) -> None:
        try:
            self._sock.sendto(packet, addr)
        except OSError:  # a client gone away: it stops keeping itself subscribed
            pass

    def close(self) -> None:
        self._sock.close()


# -- the client: a pose source ---------------------------------------------------------------


@dataclass(frozen=True, kw_only=True)
class NatNetSettings:
    """Where Motive streams and which rigid body is the robot."""

    server: str = s("127.0.0.1", _checks.host())
    """Motive's address (Motive: Streaming, Local Interface)."""
    local: str = s("127.0.0.1", _checks.host())
    """This computer's address on the network Motive streams on."""
    command_port: int = s(1510, _checks.port())
    """Motive's command port (Streaming: Command Port; 1510 by default)."""
    rigid_body: int | str = s(1, _checks.rigid_body())
    """The robot's rigid body: its streaming id, or its name in Motive."""
    up_axis: str = s("z", one_of(("z", "y")))
    """The stream's up axis (Motive: Streaming, Up Axis): "z", or "y" (Motive's default),
    turned to z up here (x, y, z)_zup = (x, -z, y) before the mocap-to-world transform."""
    connect_timeout: float = s(5.0, positive("s", 60.0))
    """How long to wait for Motive's answer to NAT_CONNECT [s]."""

    def __post_init__(self) -> None:
        check_settings(self)


_Y_UP_TO_Z_UP = (math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5))  # +90 deg about x, xyzw


class NatNetPoseSource:
    """The robot's pose from Motive's NatNet stream (unicast), through the natnet client's
    own receiving threads; latest() is the newest valid sample."""

    def __init__(self, settings: NatNetSettings) -> None:
        from natnet import NatNetClient  # the client loads only with a NatNet source

        self.settings = settings
        self._lock = threading.Lock()
        self._latest: PoseSample | None = None
        self._id: int | None = settings.rigid_body if isinstance(settings.rigid_body, int) else None
        self._count = 0
        self._client = NatNetClient(
            server_ip_address=settings.server,
            local_ip_address=settings.local,
            command_port=settings.command_port,
            use_multicast=False,
        )
        self._client.on_data_description_received_event.handlers.append(self._on_descriptions)
        self._client.on_data_frame_received_event.handlers.append(self._on_frame)
        try:
            self._client.connect(timeout=settings.connect_timeout)
        except TimeoutError:
            raise RobotError(
                f"natnet: no answer from Motive at {settings.server}:{settings.command_port} "
                f"within {settings.connect_timeout:g} s; in Motive, turn streaming on with "
                f"Transmission Type Unicast, and check the server and local addresses"
            ) from None
        except OSError as exc:
            raise RobotError(
                f"natnet: cannot open a socket on {settings.local}: {exc}; give this "
                f"computer's address on Motive's network as the local address"
            ) from None
        self._client.request_modeldef()
        self._client.run_async()

    def _on_descriptions(self, descriptions) -> None:
        if isinstance(self.settings.rigid_body, str):
            for rb in descriptions.rigid_bodies:
                if rb.name == self.settings.rigid_body:
                    self._id = rb.id_num

    def _on_frame(self, frame) -> None:
        t = time.monotonic()
        for rb in frame.rigid_bodies:
            if rb.id_num != self._id:
                continue
            if rb.tracking_valid is False:  # Motive lost the body: no pose, not an old one
                return
            p, q = rb.pos, rb.rot
            if self.settings.up_axis == "y":
                p = (p[0], -p[2], p[1])
                q = quat_multiply(_Y_UP_TO_Z_UP, q)
            with self._lock:
                self._count += 1
                self._latest = PoseSample(
                    t_receive=t,
                    t_source=float(frame.suffix.timestamp),
                    seq=int(frame.prefix.frame_number),
                    position=tuple(float(v) for v in p),  # type: ignore[arg-type]
                    quat=tuple(float(v) for v in q),  # type: ignore[arg-type]
                )
            return

    def latest(self) -> PoseSample | None:
        with self._lock:
            return self._latest

    @property
    def received(self) -> int:
        """Valid samples of the robot received so far."""
        with self._lock:
            return self._count

    def close(self) -> None:
        self._client.shutdown()
