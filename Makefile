# Two commands do everything on a fresh machine (Python, pip and gcc only):
#   make demo   geolocate the bundled example flight and write CSV, GeoJSON and a summary
#   make test   lint and run the whole test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test test-fast docs lint bench bytecode clean browser tak streams mutants geoconvert ffmpeg

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[all,test]"
	# orthority, the peer of the ortho test and bench: without its deps (it asks for opencv-python,
	# which clashes with our opencv-python-headless; its other deps are in the test extra)
	$(BIN)/python -m pip install --quiet --no-deps "orthority==0.7.0"
	# GDAL's GeoPackage validator (validate_gpkg.py), for the conformance test: without its deps (it asks
	# for GDAL's Python bindings, which need libgdal to build; the validator runs on sqlite3 alone)
	$(BIN)/python -m pip install --quiet --no-deps "gdal-utils==3.13.3.0"
	$(MAKE) --no-print-directory bytecode
	touch $(STAMP)

# The bytecode of eoloc's own modules, as pip writes it for a regular install (an editable install
# does not, and with PYTHONDONTWRITEBYTECODE set every command would compile them again: ~60 ms).
bytecode:
	$(BIN)/python -m compileall -q src/eoloc

demo: $(STAMP)
	$(BIN)/eoloc demo --out out/demo
	$(BIN)/python examples/video_demo.py --out out/demo/video
	$(BIN)/python examples/drone_demo.py --out out/demo/drone

lint: $(STAMP)
	$(BIN)/ruff check src tests bench examples

# The map test drives a real headless Chromium: Debian's chromium + chromium-driver, installed here when missing.
browser:
	@command -v chromedriver >/dev/null || { apt-get install -y -q chromium chromium-driver >/dev/null 2>&1 || \
	  { apt-get update -q >/dev/null && apt-get install -y -q chromium chromium-driver >/dev/null; }; } || \
	  { echo "install Debian's chromium and chromium-driver (as root) for the map test"; exit 1; }

# GeographicLib's GeoConvert: the reference for the MGRS test (Debian's geographiclib-tools), installed here when missing.
geoconvert:
	@command -v GeoConvert >/dev/null || { apt-get install -y -q geographiclib-tools >/dev/null 2>&1 || \
	  { apt-get update -q >/dev/null && apt-get install -y -q geographiclib-tools >/dev/null; }; } || \
	  { echo "install Debian's geographiclib-tools (as root) for the MGRS test"; exit 1; }

# FFmpeg's own ffprobe (Debian's ffmpeg): a second reader of the MPEG-TS eoloc writes, installed here when missing.
ffmpeg:
	@command -v ffprobe >/dev/null || { apt-get install -y -q --no-install-recommends ffmpeg >/dev/null 2>&1 || \
	  { apt-get update -q >/dev/null && apt-get install -y -q --no-install-recommends ffmpeg >/dev/null; }; } || \
	  { echo "install Debian's ffmpeg (as root) for the MPEG-TS conformance test"; exit 1; }

# Real network senders for the live-source test: an RTSP server (GStreamer's gst-rtsp-server,
# through Debian's python3-gi) and SRT's own tools (srt-live-transmit), installed here when missing.
STREAM_DEBS := python3-gi gir1.2-gst-rtsp-server-1.0 gstreamer1.0-plugins-good gstreamer1.0-plugins-bad srt-tools
streams:
	@{ command -v srt-live-transmit >/dev/null && /usr/bin/python3 -c "import gi; gi.require_version('GstRtspServer', '1.0')" \
	  2>/dev/null; } || { apt-get install -y -q --no-install-recommends $(STREAM_DEBS) >/dev/null 2>&1 || \
	  { apt-get update -q >/dev/null && apt-get install -y -q --no-install-recommends $(STREAM_DEBS) >/dev/null; }; } || \
	  { echo "install Debian's $(STREAM_DEBS) (as root) for the live-source test"; exit 1; }

# Real TAK servers for the CoT tests, each in a venv of its own (their pins clash with ours):
# FreeTAKServer (plain TCP; opentelemetry held at the release it was built against, 1.23 broke its
# tracer) and taky (TLS with client certificates: FreeTAKServer 2.2's TLS port reads and writes each
# client's TLS socket from different threads and stops reading a client that streams).
TAK_VENV  := .venv-tak
TAKY_VENV := .venv-taky
TAK_STAMP := $(TAK_VENV)/.installed

$(TAK_STAMP):
	$(PYTHON) -m venv $(TAK_VENV)
	$(TAK_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(TAK_VENV)/bin/python -m pip install --quiet "FreeTAKServer==2.2.1" "opentelemetry-sdk==1.22.0" \
	  "opentelemetry-api==1.22.0"
	$(PYTHON) -m venv $(TAKY_VENV)
	$(TAKY_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(TAKY_VENV)/bin/python -m pip install --quiet "taky==0.10"
	touch $(TAK_STAMP)

tak: $(TAK_STAMP)

test: $(STAMP) lint browser tak streams geoconvert ffmpeg
	$(BIN)/python -m pytest -n 2 -q

# the inner loop: no browser, no TAK server, no fresh virtual environments (markers: docs/tests.md)
test-fast: $(STAMP) lint streams geoconvert ffmpeg
	$(BIN)/python -m pytest -n 2 -q -m "not slow and not browser and not tak"

# the documentation site (MkDocs, mkdocs.yml): site/index.html
docs: $(STAMP)
	rm -rf build/walk
	EOLOC_DOCS_WALK=build/walk $(BIN)/mkdocs build --strict

bench: $(STAMP) bytecode
	$(BIN)/python bench/run_all.py

# the mutation run (issue 55): each declared mutant must be caught by its own package's tests; ~30 min
mutants: $(STAMP) browser tak streams
	$(BIN)/python bench/mutants.py

clean:
	rm -rf $(VENV) out site .pytest_cache .ruff_cache .hypothesis
