"""What the Python peers need to know of supine's CAN mapping (core/src/wire/SPEC.md §3), written independently of
the Rust code so that the peers check it rather than repeat it."""

BASE = 0x100
VERSION = 1
KINDS = ["command", "arm_state", "torso_pose", "probe", "salient_points", "health", "body_shape"]
KIND_BLOCK = {kind: i for i, kind in enumerate(KINDS)}


def crc8_sae_j1850(data):
    """CRC-8/SAE-J1850: poly 0x1D, init 0xFF, xorout 0xFF (check value 0x4B for b"123456789")."""
    crc = 0xFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1D) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ 0xFF


def e2e_crc(frame_id, data):
    """The E2E CRC in byte 0 of a frame: over the data id (version << 8 | offset, little-endian) and bytes 1..8."""
    data_id = (VERSION << 8) | (frame_id - BASE)
    return crc8_sae_j1850(bytes([data_id & 0xFF, data_id >> 8]) + bytes(data[1:8]))


assert crc8_sae_j1850(b"123456789") == 0x4B
