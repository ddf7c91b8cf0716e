"""A real RTSP server for the tests (GStreamer's gst-rtsp-server, Debian's python3-gi): serves an
MPEG-TS file at rtsp://127.0.0.1:PORT/stream as MP2T over RTP (RFC 2250, payload 33), paced by
the stream's own clock (its PCR), as an FMV encoder does. Prints 'ready' when listening.

    /usr/bin/python3 rtsp_server.py FILE.ts PORT
"""
import sys

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstRtspServer", "1.0")
from gi.repository import GLib, Gst, GstRtspServer  # noqa: E402

Gst.init(None)
path, port = sys.argv[1], sys.argv[2]
server = GstRtspServer.RTSPServer()
server.set_address("127.0.0.1")
server.set_service(port)
factory = GstRtspServer.RTSPMediaFactory()
factory.set_launch(f'( filesrc location="{path}" ! tsparse set-timestamps=true ! rtpmp2tpay name=pay0 pt=33 )')
factory.set_shared(True)
server.get_mount_points().add_factory("/stream", factory)
server.attach(None)
print("ready", flush=True)
GLib.MainLoop().run()
