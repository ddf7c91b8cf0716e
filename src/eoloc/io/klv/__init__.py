"""MISB KLV in and out: ST 0601 / EG 0104 packets (raw KLV or MPEG-TS, one stream per KLV PID),
ST 0903 VMTI targets and ST 1607 nested sets, decoded tolerantly (:mod:`.reader`), mapped into
eoloc tables (:mod:`.telemetry`), and written back (:mod:`.encode`)."""

from .eg0104 import EG0104_KEY, encode_eg0104
from .encode import build_uas_packet, encode_uas_packet, encode_vmti, frame_uas_packet, uas_items, with_target_location
from .reader import UAS_KEY, KLVIssue, KLVPacket, KLVStream, StreamNote, decode_klv_bytes, read_klv
from .telemetry import TAGS, klv_telemetry, vmti_detections

__all__ = ["EG0104_KEY", "TAGS", "UAS_KEY", "KLVIssue", "KLVPacket", "KLVStream", "StreamNote", "build_uas_packet",
           "decode_klv_bytes", "encode_eg0104", "encode_uas_packet", "encode_vmti", "frame_uas_packet",
           "klv_telemetry", "read_klv", "uas_items", "vmti_detections", "with_target_location"]
