"""The NatNet path: the twin's NatNet 4.1 packets, laid out as Motive 3.1 sends them
(robot/_natnet.py), parsed by the natnet client in unicast mode, on 127.0.0.1 only."""

from __future__ import annotations

import math
import struct
import threading
import time

import pytest

natnet = pytest.importorskip("natnet")

from roachplan.robot import (  # noqa: E402
    NatNetPoseSource,
    NatNetServer,
    NatNetSettings,
    RigidBodyFrame,
    RigidBodyModel,
    frame_packet,
    server_info_packet,
)

MARKERS = ((0.04, 0.0, 0.01), (-0.04, 0.02, 0.01), (-0.04, -0.02, 0.01))


class Served:
    """A NatNetServer served from a thread, publishing whatever frame is set."""

    def __init__(self) -> None:
        self.server = NatNetServer(
            [
                RigidBodyModel(name="other", id=3),
                RigidBodyModel(name="roach", id=7, markers=MARKERS),
            ]
        )
        self.packet: bytes | None = None
        self._stop = False
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop:
            self.server.serve()
            if self.packet is not None:
                self.server.publish(self.packet)
            time.sleep(0.005)

    def close(self) -> None:
        self._stop = True
        self._thread.join()
        self.server.close()


def test_the_server_info_is_motives_sender_server_of_natnet_4_1():
    packet = server_info_packet()
    message_id, size = struct.unpack_from("<HH", packet)
    assert (message_id, size, len(packet)) == (1, 279, 283)
    assert packet[4:10] == b"Motive" and packet[260:264] == bytes((3, 1, 0, 0))
    assert packet[264:268] == bytes((4, 1, 0, 0))


def test_the_client_parses_descriptions_and_frames_exactly_as_motive_sends_them():
    served = Served()
    client = natnet.NatNetClient(
        server_ip_address="127.0.0.1",
        local_ip_address="127.0.0.1",
        command_port=served.server.port,
        use_multicast=False,
    )
    descriptions, frames = [], []
    client.on_data_description_received_event.handlers.append(descriptions.append)
    client.on_data_frame_received_event.handlers.append(frames.append)
    try:
        client.connect(timeout=5)
        assert str(client.server_info.nat_net_protocol_version) == "4.1.0.0"
        assert client.server_info.application_name == "Motive"
        client.request_modeldef()
        bodies = [
            RigidBodyFrame(id=3, position=(9.0, 9.0, 9.0), quat=(0, 0, 0, 1), valid=False),
            RigidBodyFrame(id=7, position=(0.25, -1.5, 0.025), quat=(0.0, 0.0, 0.6, 0.8)),
        ]
        served.packet = frame_packet(
            4242,
            bodies,
            timestamp=12.345678,
            stamps=(111, 222, 333),
            marker_sets=[("roach", MARKERS), ("all", MARKERS)],
        )
        client.run_async()
        deadline = time.monotonic() + 5
        while (not frames or not descriptions) and time.monotonic() < deadline:
            time.sleep(0.02)
    finally:
        client.shutdown()
        served.close()
    (desc,) = descriptions[:1]
    # Motive's parent id -1 (no parent), which natnet 0.3.0 reads as an unsigned 32-bit int
    assert [(rb.name, rb.id_num, rb.parent_id) for rb in desc.rigid_bodies] == [
        ("other", 3, 2**32 - 1),
        ("roach", 7, 2**32 - 1),
    ]
    roach = desc.rigid_bodies[1]
    assert [c for m in roach.markers for c in m.pos] == pytest.approx(
        [c for m in MARKERS for c in m]
    )
    assert [m.name for m in roach.markers] == ["Marker1", "Marker2", "Marker3"]
    frame = frames[-1]
    assert frame.prefix.frame_number == 4242
    assert [(ms.model_name, len(ms.marker_pos_list)) for ms in frame.marker_sets] == [
        ("roach", 3),
        ("all", 3),
    ]
    other, rb = frame.rigid_bodies
    assert (other.id_num, other.tracking_valid) == (3, False)
    assert rb.id_num == 7 and rb.tracking_valid is True
    assert rb.pos == pytest.approx((0.25, -1.5, 0.025), abs=1e-7)
    assert rb.rot == pytest.approx((0.0, 0.0, 0.6, 0.8), abs=1e-7)
    assert rb.marker_error == pytest.approx(0.0002)
    assert frame.skeletons == () and frame.assets == () and frame.labeled_markers == ()
    assert frame.suffix.timestamp == 12.345678
    assert (
        frame.suffix.stamp_camera_mid_exposure,
        frame.suffix.stamp_data_received,
        frame.suffix.stamp_transmit,
    ) == (111, 222, 333)


@pytest.mark.parametrize("up_axis", ["z", "y"])
def test_the_pose_source_follows_its_rigid_body_by_name(up_axis):
    served = Served()
    try:
        source = NatNetPoseSource(
            NatNetSettings(command_port=served.server.port, rigid_body="roach", up_axis=up_axis)
        )
        try:
            half = math.sqrt(0.5)
            if up_axis == "z":  # the robot at (0.2, 0.3), 2.5 cm up, facing +y
                p, q = (0.2, 0.3, 0.025), (0.0, 0.0, half, half)
            else:  # the same robot as a y-up stream gives it: y up, z = -y_world
                p, q = (0.2, 0.025, -0.3), (-0.5, 0.5, 0.5, 0.5)
            served.packet = frame_packet(
                1, [RigidBodyFrame(id=7, position=p, quat=q)], timestamp=0.5
            )
            deadline = time.monotonic() + 5
            while source.latest() is None and time.monotonic() < deadline:
                time.sleep(0.02)
            sample = source.latest()
            assert sample is not None
            assert sample.position == pytest.approx((0.2, 0.3, 0.025), abs=1e-6)
            # forward (body x) points along world +y
            x, y, z, w = sample.quat
            assert 2 * (x * y + z * w) == pytest.approx(1.0, abs=1e-6)
            # a frame where Motive lost the body is no pose: the newest stays the old one
            served.packet = frame_packet(
                2, [RigidBodyFrame(id=7, position=(5, 5, 5), quat=q, valid=False)], timestamp=0.6
            )
            time.sleep(0.2)
            latest = source.latest()
            assert latest is not None and latest.seq == 1
        finally:
            source.close()
    finally:
        served.close()
