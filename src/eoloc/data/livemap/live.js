// eoloc's live map: Leaflet, fed by eoloc live over a WebSocket (see eoloc/service/livemap.py).
// Every drawn thing carries a CSS class (eoloc-aircraft, eoloc-aircraft-trail, eoloc-footprint,
// eoloc-centre, eoloc-target, eoloc-cep, eoloc-track, eoloc-estimate, eoloc-mover, eoloc-mover-track) and
// window.eoloc holds what
// the page knows, for scripts and tests. The circles are each fix's and estimate's CE90 (the 90 %
// circle a TAK receiver draws from the same CoT ce, 2.1460 ce); a target whose fixes are
// INCONSISTENT has no estimate marker and is listed in the panel (eoloc-inconsistent).
(function () {
  "use strict";
  const TRAIL = 2000;      // points kept per aircraft trail and per target track
  const NO_CONTACT_S = 4;  // no message at all for this long: the server is gone or the network is
  const COLOURS = {aircraft: "#1f77b4", footprint: "#ff9900", centre: "#ff9900", target: "#d62728",
                   track: "#9467bd", estimate: "#2ca02c", mover: "#e377c2"};
  const S = window.eoloc = {state: "connecting", packets: 0, messages: 0, dropped: 0, connects: 0,
                            aircraft: {}, centres: {}, targets: {}, estimates: {}, movers: {}, streams: {}, last: null};
  const map = L.map("map", {preferCanvas: false, zoomControl: true}).setView([0, 0], 2);
  L.control.scale().addTo(map);
  const groups = {};
  for (const name of ["aircraft", "footprints", "frame centres", "tracks", "targets", "estimates", "movers"]) {
    groups[name] = L.featureGroup().addTo(map);
  }
  L.control.layers(null, groups, {collapsed: false}).addTo(map);
  const drawn = {aircraft: {}, trail: {}, footprint: {}, centre: {}, target: {}, cep: {}, track: {}, estimate: {},
                 estimateCep: {}, mover: {}, moverCep: {}, moverTrack: {}};
  let fitted = false;
  let lastMessage = 0;

  // a tooltip is a node of text lines (textContent): what a stream sends is never parsed as HTML
  const tip = (...lines) => {
    const node = document.createElement("div");
    lines.filter((l) => l !== null).forEach((l, i) => {
      if (i) node.appendChild(document.createElement("br"));
      node.appendChild(document.createTextNode(String(l)));
    });
    return node;
  };
  const num = (v, d) => (typeof v === "number" && isFinite(v)) ? v.toFixed(d) : "–";

  function circle(layer, store, id, ll, radius, opts) {
    if (!(typeof radius === "number" && isFinite(radius) && radius > 0)) {
      if (store[id]) { layer.removeLayer(store[id]); delete store[id]; }
      return;
    }
    if (store[id]) { store[id].setLatLng(ll); store[id].setRadius(radius); }
    else { store[id] = L.circle(ll, Object.assign({radius: radius, weight: 1, fill: true, fillOpacity: 0.1}, opts)).addTo(layer); }
  }

  function marker(layer, store, id, ll, opts, tip) {
    if (store[id]) { store[id].setLatLng(ll); store[id].setTooltipContent(tip); }
    else { store[id] = L.circleMarker(ll, Object.assign({weight: 2, fill: true, fillOpacity: 0.9}, opts)).bindTooltip(tip).addTo(layer); }
  }

  function trail(layer, store, id, ll, opts) {
    if (!store[id]) { store[id] = L.polyline([], Object.assign({weight: 2}, opts)).addTo(layer); }
    const pts = store[id].getLatLngs();
    pts.push(ll);
    if (pts.length > TRAIL) { pts.shift(); }
    store[id].setLatLngs(pts);
  }

  function onPacket(m) {
    if (m.kind === "movers") { onMovers(m); return; }
    S.packets += 1;
    if (S.state !== "live" && S.state !== "stopped") { setState("live", "LIVE"); }
    const key = m.key;
    const st = S.streams[m.stream || key] = S.streams[m.stream || key] || {packets: 0};
    st.packets += 1; st.time_utc = m.time_utc; st.key = key;
    const bounds = [];
    for (const f of m.features) {
      const p = f.properties || {}, g = f.geometry;
      if (!g && p.what === "estimate" && p.status === "INCONSISTENT") { inconsistent(key, p); continue; }
      if (!g) { continue; }
      if (p.what === "aircraft") {
        const ll = [g.coordinates[1], g.coordinates[0]];
        S.aircraft[key] = ll;
        marker(groups.aircraft, drawn.aircraft, key, ll, {radius: 7, color: COLOURS.aircraft, className: "eoloc-aircraft"},
               tip(p.name || key, `h ${num(p.h_m, 0)} m, heading ${num(p.heading_deg, 1)}°`, p.time_utc || ""));
        trail(groups.aircraft, drawn.trail, key, ll, {color: COLOURS.aircraft, className: "eoloc-aircraft-trail"});
        bounds.push(ll);
      } else if (p.what === "footprint" && (g.type === "Polygon" || g.type === "MultiPolygon")) {
        const flip = (r) => r.map((c) => [c[1], c[0]]);  // a MultiPolygon: cut at the antimeridian
        const ring = g.type === "Polygon" ? flip(g.coordinates[0]) : g.coordinates.map((part) => flip(part[0]));
        if (drawn.footprint[key]) { drawn.footprint[key].setLatLngs(ring); }
        else { drawn.footprint[key] = L.polygon(ring, {color: COLOURS.footprint, weight: 1, fillOpacity: 0.08,
                                                       className: "eoloc-footprint"}).addTo(groups.footprints); }
        (g.type === "Polygon" ? ring : ring.flat()).forEach((ll) => bounds.push(ll));
      } else if (p.what === "frame centre") {
        const ll = [g.coordinates[1], g.coordinates[0]];
        S.centres[key] = ll;
        marker(groups["frame centres"], drawn.centre, key, ll, {radius: 4, color: COLOURS.centre, className: "eoloc-centre"},
               tip("frame centre", `h ${num(g.coordinates[2], 0)} m`));
      } else if (p.what === "target") {
        const id = `${key}/${p.target_id}`, ll = [g.coordinates[1], g.coordinates[0]];
        const t = S.targets[id] = S.targets[id] || {n: 0};
        Object.assign(t, {lat: ll[0], lon: ll[1], h_m: g.coordinates[2], cep50_m: p.cep50_m, n: t.n + 1, packet: m.index});
        marker(groups.targets, drawn.target, id, ll, {radius: 5, color: COLOURS.target, className: "eoloc-target"},
               tip(`target ${p.target_id}`, `h ${num(g.coordinates[2], 1)} m`,
                   p.cep50_m != null ? `CEP50 ${num(p.cep50_m, 1)} m, CE90 ${num(p.ce90_m, 1)} m (circle)` : null));
        circle(groups.targets, drawn.cep, id, ll, p.ce90_m, {color: COLOURS.target, className: "eoloc-cep"});
        trail(groups.tracks, drawn.track, id, ll, {color: COLOURS.track, className: "eoloc-track"});
      } else if (p.what === "estimate") {
        const id = `${key}/${p.target_id}`, ll = [g.coordinates[1], g.coordinates[0]];
        S.estimates[id] = {lat: ll[0], lon: ll[1], h_m: g.coordinates[2], cep50_m: p.cep50_m, ce90_m: p.ce90_m,
                           n: p.n_fixes, model: p.model, status: "OK"};
        marker(groups.estimates, drawn.estimate, id, ll, {radius: 6, color: COLOURS.estimate, className: "eoloc-estimate"},
               tip(`target ${p.target_id}: ${p.model || "estimate"} of ${p.n_fixes} fixes`,
                   p.cep50_m != null ? `CEP50 ${num(p.cep50_m, 1)} m, CE90 ${num(p.ce90_m, 1)} m (circle)` : null,
                   p.speed_mps != null ? `speed ${num(p.speed_mps, 1)} m/s` : null));
        circle(groups.estimates, drawn.estimateCep, id, ll, p.ce90_m, {color: COLOURS.estimate, className: "eoloc-cep"});
        flagged(id, null);
      }
    }
    if (!fitted && bounds.length) {
      const box = L.latLngBounds(bounds);  // one point (an aircraft with no footprint yet): no box to fit
      if (box.getNorth() > box.getSouth() || box.getEast() > box.getWest()) { map.fitBounds(box.pad(0.3)); }
      else { map.setView(box.getCenter(), 13); }
      fitted = true;
    }
  }

  // the movers found in the video (eoloc live --detect): where each was in its frame, its track
  function onMovers(m) {
    for (const f of m.features) {
      const p = f.properties || {}, g = f.geometry;
      if (!g || p.what !== "mover") { continue; }
      const id = `${m.key}/M${p.track_id}`, ll = [g.coordinates[1], g.coordinates[0]];
      const v = S.movers[id] = S.movers[id] || {n: 0};
      Object.assign(v, {lat: ll[0], lon: ll[1], h_m: g.coordinates[2], speed_mps: p.speed_mps,
                        heading_deg: p.heading_deg, ce90_m: p.ce90_m, n: v.n + 1, frame: p.frame});
      marker(groups.movers, drawn.mover, id, ll, {radius: 6, color: COLOURS.mover, className: "eoloc-mover"},
             tip(`mover M${p.track_id}` + (p.class ? ` ${p.class}` : ""),
                 `${num(p.speed_mps, 1)} m/s, heading ${num(p.heading_deg, 0)}°`,
                 p.ce90_m != null ? `CE90 ${num(p.ce90_m, 1)} m (circle)` : null, m.time_utc || ""));
      circle(groups.movers, drawn.moverCep, id, ll, p.ce90_m, {color: COLOURS.mover, className: "eoloc-cep"});
      trail(groups.movers, drawn.moverTrack, id, ll, {color: COLOURS.mover, className: "eoloc-mover-track"});
    }
  }

  // a target whose fixes do not agree with one point: no estimate on the map, said in the panel
  function inconsistent(key, p) {
    const id = `${key}/${p.target_id}`;
    S.estimates[id] = {status: "INCONSISTENT", n: p.n_fixes, reason: p.reason || ""};
    for (const store of [drawn.estimate, drawn.estimateCep]) {
      if (store[id]) { groups.estimates.removeLayer(store[id]); delete store[id]; }
    }
    flagged(id, `target ${p.target_id}: INCONSISTENT, no estimate (${p.n_fixes} fixes scatter ` +
                `${num(p.scatter_ratio, 0)}x more than their uncertainty allows)`);
  }

  function flagged(id, text) {
    const list = document.getElementById("eoloc-flags");
    const item = Array.from(list.children).find((li) => li.dataset.id === id);
    if (text === null) { if (item) { list.removeChild(item); } return; }
    const li = item || list.appendChild(document.createElement("li"));
    li.dataset.id = id;
    li.className = "eoloc-inconsistent";
    li.textContent = text;
  }

  function setState(state, text, detail) {
    S.state = state;
    document.body.className = `eoloc-state-${state}`;
    document.getElementById("eoloc-status").textContent = text;
    if (detail !== undefined) { document.getElementById("eoloc-detail").textContent = detail; }
  }

  function onStatus(m) {
    S.last = m;
    if (typeof m.dropped === "number") { S.dropped = m.dropped; }
    const c = m.counters || {};
    const detail = `${c.packets || 0} packets, ${c.detections || 0} detections (${c.fixes_ok || 0} located)` +
      (c.corrupt ? `, ${c.corrupt} corrupt` : "") + (c.duplicates ? `, ${c.duplicates} duplicates` : "") +
      (c.late ? `, ${c.late} late` : "") + (c.restarts ? `, ${c.restarts} encoder restarts` : "") +
      (S.dropped ? `; ${S.dropped} updates dropped (this page read too slowly)` : "");
    if (m.state === "live") { setState("live", "LIVE", detail); }
    else if (m.state === "silent") { setState("silent", `SILENT: no packet for ${num(m.quiet_s, 0)} s`, detail); }
    else if (m.state === "stopped") { setState("stopped", `STOPPED: ${m.why || "the source ended"}`, detail); }
    else { setState("waiting", "waiting for the first packet…", detail); }
    const ul = document.getElementById("eoloc-streams");
    ul.innerHTML = "";
    for (const [name, n] of Object.entries(m.streams || {})) {
      const li = document.createElement("li");
      const seen = S.streams[name] || {};
      li.textContent = `${name || "raw KLV"}: ${n} packets` + (seen.time_utc ? `, last ${seen.time_utc}` : "");
      ul.appendChild(li);
    }
  }

  let delay = 0.5;
  function connect() {
    const ws = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}${EOLOC_WS_PATH}`);
    ws.onopen = () => { S.connects += 1; delay = 0.5; };
    ws.onmessage = (ev) => {
      lastMessage = Date.now();
      S.messages += 1;
      const m = JSON.parse(ev.data);
      if (m.type === "packet") { onPacket(m); } else if (m.type === "status") { onStatus(m); }
    };
    ws.onclose = () => {
      if (S.state !== "stopped") { setState("no-contact", `NO CONTACT with eoloc: reconnecting in ${delay} s`); }
      setTimeout(connect, delay * 1000);
      delay = Math.min(delay * 2, 8);
    };
  }
  setInterval(() => {
    if (lastMessage && Date.now() - lastMessage > NO_CONTACT_S * 1000 && S.state !== "stopped" && S.state !== "no-contact") {
      setState("no-contact", `NO CONTACT with eoloc for ${Math.round((Date.now() - lastMessage) / 1000)} s`);
    }
  }, 1000);
  connect();
})();
