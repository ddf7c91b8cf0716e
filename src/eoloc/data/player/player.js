// eoloc's video player: the video and the map side by side, synced frame by frame.
// Data: window.EOLOC_PLAYER (player/data.js, written by `eoloc video`). Pixel convention: the
// centre of the top-left pixel is (0, 0), so a pixel u spans [u - 0.5, u + 0.5].
(function () {
  "use strict";
  const D = window.EOLOC_PLAYER;
  const F = D.frames;
  const N = F.t.length;
  const video = document.getElementById("video");
  const overlay = document.getElementById("overlay");
  const seek = document.getElementById("seek");
  const info = document.getElementById("info");
  const modeEl = document.getElementById("mode");
  const clickInfo = document.getElementById("click-info");
  const rectifiedIdx = Object.keys(D.rectified).map(Number).sort((a, b) => a - b);
  const period = N > 1 ? (F.t[N - 1] - F.t[0]) / (N - 1) : 0.04;
  // a tooltip's text as text (textContent): ids from the metadata are never parsed as HTML
  const textNode = (text) => { const node = document.createElement("div"); node.textContent = text; return node; };

  // -- the map ------------------------------------------------------------------------------------
  const map = L.map("map", { zoomSnap: 0, attributionControl: false });
  const overlays = {};
  if (D.mosaic) {
    overlays["mosaic of the pass"] = L.tileLayer(D.mosaic.url, {
      minZoom: 0, maxZoom: 22, maxNativeZoom: D.mosaic.max_zoom, minNativeZoom: D.mosaic.min_zoom,
      bounds: D.mosaic.bounds, className: "eoloc-mosaic" }).addTo(map);
  }
  const blank = "data:image/gif;base64,R0lGODlhAQABAAAAACH5BAEKAAEALAAAAAABAAEAAAICTAEAOw==";
  const drape = L.imageOverlay(blank, [[0, 0], [0, 0]], { opacity: 0.8, className: "eoloc-drape" }).addTo(map);
  overlays["current frame"] = drape;
  const track = L.polyline(D.track, { color: "#1f77b4", weight: 2, className: "eoloc-track" }).addTo(map);
  overlays["aircraft track"] = track;
  const footprint = L.polygon([], { color: "#ff9900", weight: 2, fill: false, className: "eoloc-footprint" });
  footprint.addTo(map);
  overlays["footprint"] = footprint;
  const centre = L.circleMarker([0, 0], { radius: 5, color: "#ff9900", fillOpacity: 1,
                                          className: "eoloc-centre" });
  const aircraft = L.circleMarker([0, 0], { radius: 7, color: "#1f77b4", fillOpacity: 1,
                                            className: "eoloc-aircraft" });
  const vmtiLayer = L.layerGroup().addTo(map);
  overlays["VMTI targets"] = vmtiLayer;
  const moverLayer = L.layerGroup().addTo(map);
  if ((D.movers || []).length) overlays["movers (found in the video)"] = moverLayer;
  const clickMarker = L.circleMarker([0, 0], { radius: 6, color: "#d62728", weight: 3, fill: false,
                                               className: "eoloc-click" });
  L.control.layers(null, overlays, { collapsed: false }).addTo(map);
  L.control.scale({ imperial: false }).addTo(map);
  const everything = L.latLngBounds([]);
  if (D.mosaic) everything.extend(D.mosaic.bounds);
  for (const k of rectifiedIdx) {
    const r = D.rectified[k];
    if (r.footprint) everything.extend(r.footprint);
  }
  for (const p of D.track) everything.extend(p); // the aircraft stays in view
  if (everything.isValid()) map.fitBounds(everything, { padding: [10, 10] });
  else map.setView([0, 0], 2);

  // -- frames and time ------------------------------------------------------------------------
  function frameAt(t) { // the frame whose presentation time is nearest t (s since the first frame)
    let lo = Math.max(lastAtOrBefore(F.t, t), 0);
    if (lo + 1 < N && Math.abs(F.t[lo + 1] - t) < Math.abs(F.t[lo] - t)) lo += 1;
    return lo;
  }
  function lastAtOrBefore(sorted, x) { // index of the last element <= x, or -1 (binary search)
    let lo = -1, hi = sorted.length - 1;
    while (lo < hi) {
      const mid = (lo + hi + 1) >> 1;
      if (sorted[mid] <= x) lo = mid; else hi = mid - 1;
    }
    return lo;
  }
  function rectifiedAtOrBefore(i) {
    const k = lastAtOrBefore(rectifiedIdx, i);
    return k < 0 ? -1 : rectifiedIdx[k];
  }
  const vmtiByTime = new Map(); // VMTI packet time -> its detections
  for (const r of D.vmti) {
    if (!vmtiByTime.has(r.video_time_s)) vmtiByTime.set(r.video_time_s, []);
    vmtiByTime.get(r.video_time_s).push(r);
  }
  const vmtiTimes = [...vmtiByTime.keys()].sort((a, b) => a - b);
  function vmtiAt(t) { // the detections of the latest VMTI packet at or before t, within the hold time
    const k = lastAtOrBefore(vmtiTimes, t + 1e-6);
    if (k < 0 || t - vmtiTimes[k] > D.vmti_hold_s) return [];
    return vmtiByTime.get(vmtiTimes[k]);
  }

  const moversByFrame = new Map(); // frame -> the movers eoloc found in it (--detect)
  const moverTracks = new Map(); // track id -> its detections in time order
  for (const r of D.movers || []) {
    if (!moversByFrame.has(r.frame)) moversByFrame.set(r.frame, []);
    moversByFrame.get(r.frame).push(r);
    if (!moverTracks.has(r.track_id)) moverTracks.set(r.track_id, []);
    moverTracks.get(r.track_id).push(r);
  }

  const state = { frame: -1, shown: -1, boxes: [], vmti: [], movers: [], moverBoxes: [], lastClick: null,
                  mode: "offline",
                  reason: "", grids: {}, ready: false };

  function sizeOverlay() {
    const r = video.getBoundingClientRect();
    overlay.width = Math.round(r.width);
    overlay.height = Math.round(r.height);
  }
  function drawBoxes() {
    const ctx = overlay.getContext("2d");
    ctx.clearRect(0, 0, overlay.width, overlay.height);
    const sx = overlay.width / D.width, sy = overlay.height / D.height;
    state.boxes = [];
    ctx.lineWidth = 2;
    ctx.font = "12px sans-serif";
    for (const r of state.vmti) {
      let x0, y0, x1, y1;
      if (r.bbox_u0 !== null && r.bbox_u1 !== null) { // the box covers pixels u0..u1, v0..v1
        x0 = r.bbox_u0 * sx; y0 = r.bbox_v0 * sy; x1 = (r.bbox_u1 + 1) * sx; y1 = (r.bbox_v1 + 1) * sy;
      } else {
        x0 = (r.u_px - 4) * sx; y0 = (r.v_px - 4) * sy; x1 = (r.u_px + 5) * sx; y1 = (r.v_px + 5) * sy;
      }
      ctx.strokeStyle = "#ff2d2d";
      ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
      ctx.fillStyle = "#ff2d2d";
      ctx.fillText(r.target_id, x0, Math.max(y0 - 3, 10));
      state.boxes.push({ target_id: r.target_id, x0: x0, y0: y0, x1: x1, y1: y1 });
    }
    state.moverBoxes = [];
    for (const r of state.movers) { // the box covers pixels u0..u1, v0..v1
      const x0 = r.bbox_u0 * sx, y0 = r.bbox_v0 * sy, x1 = (r.bbox_u1 + 1) * sx, y1 = (r.bbox_v1 + 1) * sy;
      ctx.strokeStyle = "#00e5ff";
      ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
      ctx.fillStyle = "#00e5ff";
      ctx.fillText(`M${r.track_id}`, x0, Math.min(y1 + 12, overlay.height - 2));
      state.moverBoxes.push({ track_id: r.track_id, x0: x0, y0: y0, x1: x1, y1: y1 });
    }
    if (state.lastClick && state.lastClick.frame === state.frame) {
      const x = (state.lastClick.u + 0.5) * sx, y = (state.lastClick.v + 0.5) * sy;
      ctx.strokeStyle = "#ffff00";
      ctx.beginPath(); ctx.moveTo(x - 8, y); ctx.lineTo(x + 8, y); ctx.moveTo(x, y - 8); ctx.lineTo(x, y + 8);
      ctx.stroke();
    }
  }

  function show(i) { // put frame i's geometry on the map and its VMTI on the video
    if (i === state.frame) return;
    state.frame = i;
    seek.value = String(i);
    if (F.ok[i] && F.lat[i] !== null) { aircraft.setLatLng([F.lat[i], F.lon[i]]); aircraft.addTo(map); }
    else aircraft.remove();
    const k = rectifiedAtOrBefore(i);
    state.shown = k;
    const r = k >= 0 ? D.rectified[k] : null;
    footprint.setLatLngs(r && r.footprint ? r.footprint : []);
    if (r && r.centre) { centre.setLatLng([r.centre[0], r.centre[1]]); centre.addTo(map); } else centre.remove();
    if (r && r.drape) { drape.setUrl(r.drape); drape.setBounds(L.latLngBounds(r.bounds)); }
    else drape.setUrl(blank);
    state.vmti = vmtiAt(F.t[i]);
    vmtiLayer.clearLayers();
    for (const v of state.vmti) {
      if (v.lat_deg === null) continue;
      L.circleMarker([v.lat_deg, v.lon_deg], { radius: 6, color: "#ff2d2d", fillOpacity: 0.6,
                                               className: "eoloc-vmti" })
        .bindTooltip(textNode(`target ${v.target_id}: ${v.lat_deg.toFixed(6)}, ${v.lon_deg.toFixed(6)}, ${v.h_m.toFixed(1)} m`))
        .addTo(vmtiLayer);
    }
    state.movers = moversByFrame.get(i) || [];
    moverLayer.clearLayers();
    for (const [id, rows] of moverTracks) { // each mover's ground track so far, and where it is now
      const past = rows.filter(r => r.frame <= i && r.lat_deg !== null);
      if (past.length > 1) {
        L.polyline(past.map(r => [r.lat_deg, r.lon_deg]), { color: "#00e5ff", weight: 2,
                                                            className: "eoloc-mover-track" }).addTo(moverLayer);
      }
    }
    for (const r of state.movers) {
      if (r.lat_deg === null) continue;
      L.circleMarker([r.lat_deg, r.lon_deg], { radius: 6, color: "#00e5ff", fillOpacity: 0.6,
                                               className: "eoloc-mover" })
        .bindTooltip(textNode(`mover ${r.track_id}: ${r.lat_deg.toFixed(6)}, ${r.lon_deg.toFixed(6)}, ` +
                              `${r.speed_mps.toFixed(1)} m/s to ${r.heading_deg.toFixed(0)}°`))
        .addTo(moverLayer);
    }
    drawBoxes();
    const note = !F.ok[i] ? " · no pose (outside the metadata or in a gap)" :
      (k === i ? "" : (k >= 0 ? ` · map shows rectified frame ${k}` : " · no rectified frame yet"));
    info.textContent = `frame ${i} / ${N - 1} · ${F.t[i].toFixed(3)} s${note}` +
      (state.vmti.length ? ` · ${state.vmti.length} VMTI target(s)` : "") +
      (state.movers.length ? ` · ${state.movers.length} mover(s)` : "");
  }

  function onFrame(now, meta) { // called by the browser for every frame it presents
    show(frameAt(meta.mediaTime));
    video.requestVideoFrameCallback(onFrame);
  }
  if ("requestVideoFrameCallback" in video) video.requestVideoFrameCallback(onFrame);
  else video.addEventListener("timeupdate", () => show(frameAt(video.currentTime)));
  video.addEventListener("seeked", () => { if (video.paused) show(frameAt(video.currentTime)); });

  function goTo(i) { // seek to frame i (just after its start, so the decoder shows it)
    i = Math.max(0, Math.min(N - 1, i));
    video.pause();
    video.currentTime = F.t[i] + Math.min(period / 4, 0.001);
  }
  seek.max = String(N - 1);
  seek.addEventListener("input", () => goTo(Number(seek.value)));
  const playBtn = document.getElementById("play");
  playBtn.addEventListener("click", () => { if (video.paused) video.play(); else video.pause(); });
  video.addEventListener("play", () => { playBtn.textContent = "❚❚"; });
  video.addEventListener("pause", () => { playBtn.textContent = "▶"; });
  document.getElementById("prev").addEventListener("click", () => goTo(state.frame - 1));
  document.getElementById("next").addEventListener("click", () => goTo(state.frame + 1));
  document.getElementById("opacity").addEventListener("input", (e) => drape.setOpacity(Number(e.target.value) / 100));
  document.addEventListener("keydown", (e) => {
    if (e.target.tagName === "INPUT") return;
    if (e.key === " ") { e.preventDefault(); playBtn.click(); }
    else if (e.key === "ArrowLeft") goTo(state.frame - 1);
    else if (e.key === "ArrowRight") goTo(state.frame + 1);
  });
  video.addEventListener("loadedmetadata", () => { sizeOverlay(); drawBoxes(); });
  video.addEventListener("loadeddata", () => { state.ready = true; if (state.frame < 0) show(0); });
  window.addEventListener("resize", () => { sizeOverlay(); drawBoxes(); map.invalidateSize(); });

  // -- clicks: the ground point of a pixel ---------------------------------------------------------
  const apiRequest = (i, u, v) => {
    const pose = { lat_deg: F.lat[i], lon_deg: F.lon[i], h_m: F.h[i], yaw_deg: F.yaw[i], pitch_deg: F.pitch[i],
                   roll_deg: F.roll[i], gimbal_deg: ["g1", "g2", "g3"].filter((g) => g in F).map((g) => F[g][i]) };
    let stop;
    if (D.stop.dem !== undefined) stop = { dem: D.stop.dem };
    else if (D.stop.target_height_m !== undefined) stop = { target_height_m: D.stop.target_height_m };
    else stop = { target_height_m: F.ground_h[i] };
    const body = { pose: pose, gimbal: D.gimbal, pixels: [[u, v]], stop: stop };
    if (D.camera) body.camera = Object.assign({}, D.camera, { fx: F.fx[i], fy: F.fy[i] });
    return body;
  };
  async function locateApi(i, u, v) {
    const r = await fetch("/v1/locate", { method: "POST", headers: { "Content-Type": "application/json" },
                                          body: JSON.stringify(apiRequest(i, u, v)) });
    const js = await r.json();
    if (!r.ok) throw new Error(js.problems ? js.problems.map((p) => `${p.field}: ${p.message}`).join("; ") : r.status);
    const f = js.fixes[0];
    return f.status === "OK" ? { lat: f.lat_deg, lon: f.lon_deg, h: f.h_m, how: "eoloc serve /v1/locate (exact)" }
      : { error: `no ground point: ${f.status}` };
  }
  function decode(b64) {
    const bin = atob(b64), bytes = new Uint8Array(bin.length);
    for (let k = 0; k < bin.length; k++) bytes[k] = bin.charCodeAt(k);
    return new Float32Array(bytes.buffer);
  }
  window.eolocGrid = function (index, g) { // called by player/grid/NNNNNN.js
    state.grids[index] = { u: g.u, v: g.v, lat0: g.lat0, lon0: g.lon0, dlat: decode(g.dlat), dlon: decode(g.dlon),
                           h: decode(g.h), cell: decode(g.cell), px_m: decode(g.px_m) };
    const waiting = state.gridWaiters && state.gridWaiters[index];
    if (waiting) { delete state.gridWaiters[index]; waiting.forEach((fn) => fn()); }
  };
  function loadGrid(i) {
    if (state.grids[i]) return Promise.resolve(state.grids[i]);
    return new Promise((resolve, reject) => {
      state.gridWaiters = state.gridWaiters || {};
      (state.gridWaiters[i] = state.gridWaiters[i] || []).push(() => resolve(state.grids[i]));
      const s = document.createElement("script");
      s.src = D.rectified[i].grid;
      s.onerror = () => reject(new Error(`cannot load ${D.rectified[i].grid}`));
      document.head.appendChild(s);
    });
  }
  function cellOf(nodes, x) { // the grid cell holding x, and where in it (may reach past an edge by half a pixel)
    let j = 0;
    while (j < nodes.length - 2 && x > nodes[j + 1]) j++;
    return [j, (x - nodes[j]) / (nodes[j + 1] - nodes[j])];
  }
  async function locateOffline(i, u, v) {
    if (!D.rectified[i]) {
      return { error: `frame ${i} has no ground grid (only rectified frames have one): step to a rectified frame, ` +
               "or serve the page for exact clicks on every frame" };
    }
    const g = await loadGrid(i);
    const C = g.u.length;
    const [j, a] = cellOf(g.u, u), [k, b] = cellOf(g.v, v);
    const cell = g.cell[k * (C - 1) + j];
    if (Number.isNaN(cell)) return { error: "no ground at this pixel (sky, or off the DEM)" };
    if (cell < 0) {
      return { error: "a terrain edge crosses this part of the frame: the offline grid cannot say which side " +
               "the pixel lands on; serve the page for an exact answer" };
    }
    const at = (arr) => (1 - a) * (1 - b) * arr[k * C + j] + a * (1 - b) * arr[k * C + j + 1] +
      (1 - a) * b * arr[(k + 1) * C + j] + a * b * arr[(k + 1) * C + j + 1];
    const pxm = g.px_m[k * (C - 1) + j];
    return { lat: g.lat0 + at(g.dlat), lon: g.lon0 + at(g.dlon), h: at(g.h),
             how: `offline ground grid: checked to ${cell.toFixed(2)} m in this cell, where a pixel is ` +
                  `${pxm.toFixed(1)} m on the ground` };
  }
  overlay.addEventListener("click", async (e) => {
    const r = overlay.getBoundingClientRect();
    const u = (e.clientX - r.left) * D.width / r.width - 0.5;
    const v = (e.clientY - r.top) * D.height / r.height - 0.5;
    const i = state.frame;
    const click = { frame: i, u: u, v: v, pending: true };
    state.lastClick = click;
    drawBoxes();
    let res;
    try {
      if (!F.ok[i]) res = { error: `frame ${i} has no pose` };
      else res = state.mode === "api" ? await locateApi(i, u, v) : await locateOffline(i, u, v);
    } catch (err) {
      res = { error: String(err.message || err) };
    }
    Object.assign(click, res, { pending: false });
    if (res.error) {
      clickMarker.remove();
      clickInfo.textContent = `frame ${i}, pixel (${u.toFixed(1)}, ${v.toFixed(1)}): ${res.error}`;
      return;
    }
    clickMarker.setLatLng([res.lat, res.lon]).addTo(map);
    clickMarker.bindTooltip(`${res.lat.toFixed(7)}, ${res.lon.toFixed(7)}, ${res.h.toFixed(1)} m`);
    clickInfo.textContent = `frame ${i}, pixel (${u.toFixed(1)}, ${v.toFixed(1)})\n` +
      `${res.lat.toFixed(7)}°, ${res.lon.toFixed(7)}°, ${res.h.toFixed(1)} m (ellipsoidal) · ${res.how}`;
  });

  // -- served or offline ---------------------------------------------------------------------------
  function setMode(mode, reason) {
    state.mode = mode;
    state.reason = reason;
    modeEl.className = mode;
    modeEl.innerHTML = "";
    modeEl.append(mode === "api" ? "Clicks: exact, through eoloc serve's /v1/locate." : `Clicks: offline ground grids (${reason}). For exact clicks on every frame run `);
    if (mode !== "api" && D.serve) {
      const c = document.createElement("code");
      c.textContent = D.serve;
      modeEl.append(c);
    }
  }
  setMode("offline", "not served");
  if (location.protocol.startsWith("http")) {
    fetch("/v1/health").then((r) => r.json()).then((h) => {
      if (D.stop.dem !== undefined && !(h.dems || []).includes(D.stop.dem)) {
        setMode("offline", `the server has no DEM named ${D.stop.dem}`);
      } else if (!D.camera && !h.config) {
        setMode("offline", "the server has no camera config");
      } else setMode("api", "");
    }).catch(() => setMode("offline", "no eoloc API on this server"));
  }

  // for tests and scripts: the player's state and its map
  window.eolocPlayer = { state: state, map: map, video: video, goTo: goTo, frameAt: frameAt, apiRequest: apiRequest,
                         layers: { footprint: footprint, centre: centre, aircraft: aircraft, drape: drape,
                                   vmti: vmtiLayer, movers: moverLayer, click: clickMarker, track: track } };
})();
