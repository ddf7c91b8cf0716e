"""MISB KLV in and out: ST 0601 / EG 0104 packets (raw KLV or MPEG-TS, one stream per KLV PID),
ST 0903 VMTI targets and ST 1607 nested sets, decoded tolerantly (:mod:`.reader`), mapped into
eoloc tables (:mod:`.tables`), and written back (:mod:`.encode`); for archives, the same packets as
column arrays at compiled speed (:mod:`.columnar`)."""

from ...util.lazy import lazy_attributes

_WHERE = {  # name -> submodule: loaded on first use (the CLI imports .conventions alone at start-up)
    "EG0104_KEY": "eg0104", "encode_eg0104": "eg0104",
    "build_uas_packet": "encode", "encode_uas_packet": "encode", "encode_vmti": "encode",
    "frame_uas_packet": "encode", "uas_items": "encode", "with_target_location": "encode",
    "UAS_KEY": "reader", "KLVIssue": "reader", "KLVPacket": "reader", "KLVStream": "reader",
    "StreamNote": "reader", "decode_klv_bytes": "reader", "read_klv": "reader",
    "KLVColumns": "columnar", "decode_klv_columns": "columnar", "read_klv_columns": "columnar",
    "Tag": "st0601", "VIEW": "tables", "klv_telemetry": "tables", "vmti_detections": "tables",
}


__getattr__ = lazy_attributes(__name__, _WHERE)


__all__ = ["EG0104_KEY", "UAS_KEY", "VIEW", "KLVColumns", "KLVIssue", "KLVPacket", "KLVStream", "StreamNote", "Tag",
           "build_uas_packet", "decode_klv_bytes", "decode_klv_columns", "encode_eg0104", "encode_uas_packet",
           "encode_vmti", "frame_uas_packet", "klv_telemetry", "read_klv", "read_klv_columns", "uas_items",
           "vmti_detections", "with_target_location"]
