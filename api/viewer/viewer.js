// Aisle map viewer: the map's layers over Leaflet (CRS.Simple: one unit one metre, latlng = [y, x]), kept live
// from the map's event stream, and the map's answers (semantics, bins, routes, history) on click.
"use strict";

const KEY_STORAGE = "aisle.apiKey";
const FEATURE_PAGE = 10000;  // the API's largest page of /features
const OVERLAYS = [  // grid layers drawn as images: [viewer layer, store layer, entropy layer for transparency]
  ["occupancy", "occupancy", null],
  ["semantic", "semantic_label", "semantic_entropy"],
];
const LAYERS = [  // [id, title, swatch colour, feature kinds]
  ["occupancy", "Occupancy", "#777", []],
  ["semantic", "Semantic labels", "#9467bd", []],
  ["regions", "Place regions", "#78c878", ["corridor", "junction", "room", "open_area", "region"]],
  ["floorplan", "Floor-plan units and doors", "#8c564b", ["unit", "door"]],
  ["walls", "Walls", "#000000", ["wall"]],
  ["racks", "Rack rows and uprights", "#1f77b4", ["rack_row", "pillar"]],
  ["bins", "Bins", "#e68c28", ["bin"]],
  ["places", "Docks, gates, chargers", "#2ca02c", ["dock", "gate", "charger"]],
  ["objects", "Objects", "#dc006e", ["object"]],
  ["topology", "Topology graph", "#444444", []],
  ["robots", "Robots", "#d62728", []],
];
const NOT_DRAWN = new Set(["bin_state", "load_scene"]);  // feature kinds a revision event need not refetch
const REGION_COLOURS = { corridor: "#78c878", junction: "#466ee6", storage: "#f0aa3c", room: "#bea0e6",
  open_area: "#96dce6", unidentified: "#c8c8c8" };
const KIND_STYLE = {
  wall: { color: "#000", weight: 3 }, rack_row: { color: "#1f77b4", weight: 2, fillOpacity: 0.15 },
  pillar: { color: "#1f77b4", weight: 1 }, dock: { color: "#2ca02c", weight: 5 }, gate: { color: "#17becf", weight: 5 },
  unit: { color: "#8c564b", weight: 2, fillOpacity: 0.08, dashArray: "6 3" }, door: { color: "#8c564b", weight: 5 },
};

const state = {
  map: new URLSearchParams(location.search).get("map"),
  key: sessionStorage.getItem(KEY_STORAGE),
  shown: null,          // revision id drawn (null: nothing yet)
  latest: null,         // newest revision id seen
  history: null,        // revision id the slider shows, null when live
  features: {},         // kind -> GeoJSON features drawn
  overlays: {},         // viewer layer -> {image, revision}
  stream: null,
  pendingKinds: new Set(), pendingLayers: new Set(), pendingTopology: false, refreshTimer: null,
  routePick: null,
  placePick: false,     // the next click on the map puts the place of the place form there
  blocks: [],           // the blocks shown (GET /topology/blocked)
  retry: null,          // the write that waits for a write key
};

const leaflet = L.map("map", { crs: L.CRS.Simple, preferCanvas: true, minZoom: -4, maxZoom: 8, zoomSnap: 0.25,
  attributionControl: false, zoomControl: true });
leaflet.createPane("grids").style.zIndex = 350;  // grid layers under the features (overlay pane: 400)
leaflet.setView([0, 0], 2);
L.control.scale({ metric: true, imperial: false, maxWidth: 150, position: "bottomleft" }).addTo(leaflet);
const groups = {};
for (const [id] of LAYERS) groups[id] = id === "bins" ? new window.BinLayer() : L.layerGroup();
const routeLayer = L.layerGroup().addTo(leaflet), diffLayer = L.layerGroup().addTo(leaflet);
const visible = new Set(LAYERS.map(([id]) => id));
window.aisleViewer = { state, leaflet, groups, ready: false, errors: [] };

// ---- talking to the API ------------------------------------------------------------------------------------

class AuthNeeded extends Error {}

async function api(path, { method = "GET", body } = {}) {
  const headers = {};
  if (state.key) headers["X-API-Key"] = state.key;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const response = await fetch(path, { method, headers, body: body === undefined ? undefined : JSON.stringify(body) });
  if (response.status === 401 || (response.status === 403 && method !== "GET")) {
    const detail = await errorText(response);
    if (method === "GET") state.retry = null;  // the prompt is for reading: the page starts again with the key
    askForKey(response.status === 403 || method !== "GET" ? `Changing the map needs a write key: ${detail}`
      : `This server needs an API key to read the map: ${detail}`);
    throw new AuthNeeded(detail);
  }
  return response;
}

async function json(path, options) {
  const response = await api(path, options);
  if (!response.ok) throw new Error(`${path}: ${response.status} ${await errorText(response)}`);
  return response.json();
}

async function errorText(response) {
  try {
    const body = await response.json();
    return typeof body.detail === "string" ? body.detail : JSON.stringify(body.detail);
  } catch (_) { return response.statusText; }
}

const mapPath = (rest) => `/v1/maps/${encodeURIComponent(state.map)}${rest}`;
const atRevision = (path) => (state.history === null ? path
  : path + (path.includes("?") ? "&" : "?") + "revision=" + state.history);

// ---- key prompt ----------------------------------------------------------------------------------------------

function askForKey(reason) {
  document.getElementById("key-reason").textContent = reason;
  document.getElementById("key-dialog").hidden = false;
  document.getElementById("key-input").focus();
}

document.getElementById("key-form").addEventListener("submit", (event) => {
  event.preventDefault();
  const key = document.getElementById("key-input").value.trim();
  if (key) sessionStorage.setItem(KEY_STORAGE, key); else sessionStorage.removeItem(KEY_STORAGE);
  state.key = key || null;
  document.getElementById("key-dialog").hidden = true;
  const retry = state.retry;
  state.retry = null;
  if (retry) retry().catch(report); else start();  // a write that asked for the key is tried again with it
});
document.getElementById("key-cancel").addEventListener("click", () => {
  state.retry = null;
  document.getElementById("key-dialog").hidden = true;
});
document.getElementById("change-key").addEventListener("click", () => askForKey("Enter an API key (or none)."));

// ---- layers and legend -------------------------------------------------------------------------------------

function buildLegend() {
  const list = document.getElementById("layers");
  list.replaceChildren();
  for (const [id, title, colour] of LAYERS) {
    const item = document.createElement("li");
    item.dataset.layer = id;
    item.innerHTML = `<label><input type="checkbox" data-layer="${id}"> <span class="swatch"
      style="background:${colour}"></span>${title} <span class="count"></span></label><ul class="legend"></ul>`;
    const box = item.querySelector("input");
    box.checked = visible.has(id);
    box.addEventListener("change", () => toggle(id, box.checked));
    list.appendChild(item);
    if (visible.has(id)) groups[id].addTo(leaflet);
  }
}

function toggle(id, on) {
  if (on) { visible.add(id); groups[id].addTo(leaflet); } else { visible.delete(id); groups[id].remove(); }
}

function setLegend(id, count, entries) {
  const item = document.querySelector(`#layers li[data-layer="${id}"]`);
  item.querySelector(".count").textContent = count === null ? "" : `(${count})`;
  item.classList.toggle("empty", count === 0);
  item.querySelector(".legend").innerHTML = (entries || []).map(([name, colour]) =>
    `<li><span class="swatch" style="background:${colour}"></span>${name}</li>`).join("");
}

// ---- drawing ---------------------------------------------------------------------------------------------------

const latlng = ([x, y]) => [y, x];
const rgb = (c) => `rgb(${c[0]},${c[1]},${c[2]})`;

async function drawOverlay(id, layerName, entropyName, layerInfo) {
  const group = groups[id];
  if (!layerInfo[layerName]) { group.clearLayers(); state.overlays[id] = null; setLegend(id, 0); return; }
  const info = layerInfo[layerName];
  const query = entropyName && layerInfo[entropyName] ? `?entropy=${entropyName}` : "";
  const response = await api(atRevision(mapPath(`/layers/${layerName}/overlay.png${query}`)));
  if (!response.ok) throw new Error(`layer ${layerName}: ${response.status} ${await errorText(response)}`);
  const url = URL.createObjectURL(await response.blob());
  const [minX, minY, maxX, maxY] = info.extent;
  const image = L.imageOverlay(url, [[minY, minX], [maxY, maxX]], { className: `aisle-layer-${id}`, pane: "grids" });
  const previous = state.overlays[id];
  state.overlays[id] = { image, url, revision: info.revision_id };
  const loaded = new Promise((resolve) => {
    image.once("load error", () => {  // the old picture stays until the new one is drawn, so nothing flickers
      if (previous) { group.removeLayer(previous.image); URL.revokeObjectURL(previous.url); }
      resolve();
    });
  });
  image.addTo(group);
  if (leaflet.hasLayer(group)) await loaded;
  const classes = info.meta.classes, colours = info.meta.colours;
  setLegend(id, null, classes && colours ? classes.map((name, i) => [name, rgb(colours[i])]).slice(1) : []);
}

async function drawOverlays(names) {
  const infos = await json(atRevision(mapPath("/layers")));
  const layerInfo = Object.fromEntries(infos.map((info) => [info.name, info]));
  await Promise.all(OVERLAYS.filter(([, name, entropy]) => !names || names.has(name) || names.has(entropy))
    .map(([id, name, entropy]) => drawOverlay(id, name, entropy, layerInfo)));
  return layerInfo;
}

// Every feature, a page at a time from /features (live reads are answered from the server's memory).
async function loadAllFeatures() {
  const features = [];
  for (let offset = 0; offset !== null;) {
    const page = await json(atRevision(mapPath(`/features?limit=${FEATURE_PAGE}&offset=${offset}`)));
    features.push(...page.features);
    offset = page.next_offset;
  }
  state.features = {};
  for (const feature of features) (state.features[feature.properties.kind] ||= []).push(feature);
  drawFeatures(null);
  return features;
}

// Only what changed in `kinds` since revision `since`, merged into our copy (or all of those kinds).
async function loadFeatures(kinds, since = null) {
  const query = [...(kinds || [])].map((k) => "kind=" + encodeURIComponent(k));
  if (kinds && since !== null) query.push("since=" + since);
  const response = await api(atRevision(mapPath("/layout?" + query.join("&"))));
  if (response.status === 422) return loadAllFeatures();  // a kind this server does not know yet
  if (!response.ok) throw new Error(`layout: ${response.status} ${await errorText(response)}`);
  const collection = await response.json();
  if (collection.removed === undefined) for (const kind of kinds) state.features[kind] = [];
  else {
    for (const kind of kinds) {
      const gone = new Set(collection.removed[kind] || []);
      for (const f of collection.features) if (f.properties.kind === kind) gone.add(f.properties.key);
      state.features[kind] = (state.features[kind] || []).filter((f) => !gone.has(f.properties.key));
    }
  }
  for (const feature of collection.features) (state.features[feature.properties.kind] ||= []).push(feature);
  drawFeatures(new Set([...kinds]));
}

function layerOfKind(kind) {
  const found = LAYERS.find(([, , , kinds]) => kinds.includes(kind));
  return found ? found[0] : null;
}

function drawFeatures(kinds) {
  const ids = kinds ? new Set([...kinds].map(layerOfKind).filter(Boolean)) : new Set(LAYERS.map(([id]) => id));
  for (const [id, , , layerKinds] of LAYERS) {
    if (!ids.has(id) || !layerKinds.length) continue;
    const features = layerKinds.flatMap((kind) => state.features[kind] || []);
    if (id === "bins") {
      groups.bins.setBins(features);
      document.getElementById("bin-ids").innerHTML = features.length <= 20000
        ? features.map((f) => `<option value="${f.properties.key}">`).join("") : "";
      setLegend(id, features.length);
      continue;
    }
    groups[id].clearLayers();
    if (features.length) L.geoJSON(features, { style: styleOf, pointToLayer: pointOf,
      coordsToLatLng: (c) => L.latLng(c[1], c[0]) }).addTo(groups[id]);
    const entries = id === "regions" ? Object.entries(REGION_COLOURS)
      .filter(([label]) => features.some((f) => regionLabel(f) === label)) : [];
    setLegend(id, features.length, entries);
  }
}

const regionLabel = (f) => f.properties.label || f.properties.kind;

function styleOf(feature) {
  const kind = feature.properties.kind;
  if (layerOfKind(kind) === "regions") {
    const colour = REGION_COLOURS[regionLabel(feature)] || "#999";
    return { color: colour, weight: 1, fillColor: colour, fillOpacity: 0.25 };
  }
  return KIND_STYLE[kind] || { color: "#555", weight: 2 };
}

function pointOf(feature, at) {
  const kind = feature.properties.kind;
  if (kind === "object") {
    const age = objectAge(feature);
    return L.circleMarker(at, { radius: 6, color: "#dc006e", weight: 2, fillOpacity: age === null ? 0.6
      : Math.max(0.1, 0.8 - age / 120) }).bindTooltip(`${feature.properties.class || "object"} ${feature.properties.key}`
      + (age === null ? "" : `, seen ${Math.round(age)} s ago`));
  }
  const style = KIND_STYLE[kind] || {};
  return L.circleMarker(at, { radius: kind === "pillar" ? 2 : 7, color: style.color || "#2ca02c", weight: 2,
    fillOpacity: 0.7 }).bindTooltip(`${kind} ${feature.properties.key}${approachText(feature)}`);
}

function approachText(feature) {
  const pose = feature.properties.approach_pose;
  return Array.isArray(pose) ? `, approached at ${Math.round(pose[2] * 180 / Math.PI)}°` : "";
}

function objectAge(feature) {
  const ns = feature.properties.last_seen_ns;
  return typeof ns === "number" ? Math.max(0, Date.now() / 1000 - ns / 1e9) : null;
}

async function drawTopology() {
  const response = await api(atRevision(mapPath("/topology?format=geojson")));
  groups.topology.clearLayers();
  if (!response.ok) { setLegend("topology", 0); return; }
  const graph = await response.json();
  L.geoJSON(graph, {
    coordsToLatLng: (c) => L.latLng(c[1], c[0]),
    style: (f) => ({ color: f.properties.blocked ? "#d00" : "#444", weight: 2, dashArray: f.properties.blocked
      ? "4 4" : null }),
    pointToLayer: (f, at) => L.circleMarker(at, { radius: 4, color: f.properties.blocked ? "#d00" : "#444",
      fillOpacity: 0.9, weight: 1 }).bindTooltip(`${f.properties.kind} ${f.id}`),
  }).addTo(groups.topology);
  setLegend("topology", graph.features.filter((f) => f.geometry.type === "Point").length);
}

async function drawRobots() {
  const response = await api(mapPath("/robots"));
  if (!response.ok) { setLegend("robots", 0); return; }
  const robots = (await response.json()).robots;
  groups.robots.clearLayers();
  for (const robot of robots) {
    const track = robot.track.map((p) => [p.y_m, p.x_m]);
    if (track.length > 1) L.polyline(track, { color: "#d62728", weight: 2, opacity: 0.6 }).addTo(groups.robots);
    const { x_m: x, y_m: y, yaw_rad: yaw } = robot.pose;
    L.polyline([[y, x], [y + Math.sin(yaw), x + Math.cos(yaw)]], { color: "#d62728", weight: 3 }).addTo(groups.robots);
    L.circleMarker([y, x], { radius: 7, color: "#d62728", fillOpacity: 0.9 })
      .bindTooltip(`${robot.robot} (${x.toFixed(2)}, ${y.toFixed(2)})`).addTo(groups.robots);
  }
  setLegend("robots", robots.length);
}

function showRevision(revision) {
  document.getElementById("revision-id").textContent = revision ? revision.id : "–";
  document.getElementById("revision-time").textContent = revision
    ? new Date(revision.created_at).toLocaleTimeString() + (state.history === null ? "" : " (history)") : "";
}

// ---- loading and following -------------------------------------------------------------------------------------

async function loadAll() {
  const [layerInfo, features] = await Promise.all([drawOverlays(null), loadAllFeatures(), drawTopology(),
    drawRobots().catch(() => setLegend("robots", 0)), drawBlocks()]);
  return extentOf(layerInfo, features);
}

/** [min x, min y, max x, max y] of the grid layers and features, metres; null for an empty map. */
function extentOf(layerInfo, features) {
  const box = [Infinity, Infinity, -Infinity, -Infinity];
  const add = (x, y) => {
    box[0] = Math.min(box[0], x); box[1] = Math.min(box[1], y); box[2] = Math.max(box[2], x); box[3] = Math.max(box[3], y);
  };
  for (const info of Object.values(layerInfo)) { add(info.extent[0], info.extent[1]); add(info.extent[2], info.extent[3]); }
  const walk = (c) => (typeof c[0] === "number" ? add(c[0], c[1]) : c.forEach(walk));
  if (!Object.keys(layerInfo).length) for (const f of features) if (f.geometry) walk(f.geometry.coordinates);
  return box[0] <= box[2] ? box : null;
}

async function start() {
  try {
    if (state.stream) state.stream.abort();
    const maps = await json("/v1/maps");
    const select = document.getElementById("map-select");
    select.innerHTML = maps.map((m) => `<option>${m.name}</option>`).join("");
    if (!maps.length) { setLive("down", "no maps yet"); setTimeout(start, 2000); return; }
    if (!state.map || !maps.some((m) => m.name === state.map)) state.map = maps[0].name;
    select.value = state.map;
    const detail = await json(mapPath(""));
    state.latest = detail.latest_revision_id;
    state.shown = state.latest;
    const extent = await loadAll();
    if (!state.fitted && extent) {
      const [minX, minY, maxX, maxY] = extent;
      leaflet.fitBounds([[minY, minX], [maxY, maxX]], { padding: [10, 10], animate: false });
      state.fitted = true;
    }
    showRevision(detail.latest_revision);
    await setupHistory();
    follow();
    requestAnimationFrame(() => { window.aisleViewer.readyAt = performance.now(); });  // drawn on the next frame
    window.aisleViewer.ready = true;
  } catch (error) {
    if (!(error instanceof AuthNeeded)) report(error);
  }
}

function setLive(kind, text) {
  document.getElementById("live-dot").className = "dot " + kind;
  document.getElementById("live-state").textContent = text;
}

// Server-Sent Events read with fetch, so the API key goes in a header and Last-Event-ID is ours to send.
async function follow() {
  const controller = new AbortController();
  state.stream = controller;
  let lastId = state.latest ?? 0;
  while (!controller.signal.aborted) {
    try {
      const headers = { Accept: "text/event-stream", "Last-Event-ID": String(lastId) };
      if (state.key) headers["X-API-Key"] = state.key;
      const response = await fetch(mapPath("/events"), { headers, signal: controller.signal });
      if (response.status === 401) { askForKey("This server needs an API key to follow the map."); return; }
      if (response.status === 409) { setLive("down", "map replaced; reloading"); state.fitted = false; start(); return; }
      if (!response.ok) throw new Error(`events: ${response.status}`);
      setLive("live", "live");
      const reader = response.body.pipeThrough(new TextDecoderStream()).getReader();
      let buffer = "";
      for (;;) {
        const { value, done } = await reader.read();
        if (done) break;
        buffer += value.replace(/\r\n?/g, "\n");
        let end;
        while ((end = buffer.indexOf("\n\n")) >= 0) {
          const block = buffer.slice(0, end);
          buffer = buffer.slice(end + 2);
          const event = parseEvent(block);
          if (event.id) lastId = Number(event.id);
          if (event.event === "revision" && event.data) revisionArrived(JSON.parse(event.data));
        }
      }
    } catch (error) {
      if (controller.signal.aborted) return;
    }
    setLive("down", "reconnecting");
    await new Promise((resolve) => setTimeout(resolve, 1000));
  }
}

function parseEvent(block) {
  const event = {};
  for (const line of block.split("\n")) {
    if (!line || line.startsWith(":")) continue;
    const colon = line.indexOf(":");
    const field = colon < 0 ? line : line.slice(0, colon);
    const value = colon < 0 ? "" : line.slice(colon + 1).replace(/^ /, "");
    event[field] = field === "data" && event.data !== undefined ? event.data + "\n" + value : value;
  }
  return event;
}

function revisionArrived(event) {
  state.latest = Math.max(state.latest ?? 0, event.revision_id);
  const slider = document.getElementById("history");
  slider.max = state.latest;
  if (state.history === null) slider.value = state.latest;
  for (const name of event.layers_updated) state.pendingLayers.add(name);
  // bin states and bay scenes change often and are not drawn (the bin card reads a bin's state)
  for (const kind of Object.keys(event.features)) if (!NOT_DRAWN.has(kind)) state.pendingKinds.add(kind);
  state.pendingTopology ||= event.topology_changed;
  state.pendingEvent = event;
  if (state.history === null && !state.refreshTimer && !state.refreshing) state.refreshTimer = setTimeout(refresh, 100);
}

// Redraw only what the new revisions changed: their layers, their feature kinds, the graph if it changed.
async function refresh() {
  state.refreshTimer = null;
  state.refreshing = true;  // one refresh at a time, so an older answer never lands after a newer one
  const layers = state.pendingLayers, kinds = state.pendingKinds, topology = state.pendingTopology;
  const event = state.pendingEvent;
  state.pendingLayers = new Set(); state.pendingKinds = new Set(); state.pendingTopology = false;
  try {
    const work = [];
    if (OVERLAYS.some(([, name, entropy]) => layers.has(name) || layers.has(entropy))) work.push(drawOverlays(layers));
    if (kinds.delete("robot")) work.push(drawRobots());  // the occupancy stage stored where the robots are
    if (kinds.size) work.push(loadFeatures(kinds, state.shown));
    if (topology) work.push(drawTopology(), drawBlocks());
    await Promise.all(work);
    state.shown = event.revision_id;
    showRevision({ id: event.revision_id, created_at: event.created_at });
  } catch (error) {
    if (!(error instanceof AuthNeeded)) report(error);
    kinds.forEach((kind) => state.pendingKinds.add(kind));  // asked again with the next refresh
    layers.forEach((name) => state.pendingLayers.add(name));
    state.pendingTopology ||= topology;
  } finally {
    state.refreshing = false;
    if (state.pendingEvent !== event && state.history === null) state.refreshTimer = setTimeout(refresh, 0);
  }
}

// ---- history -----------------------------------------------------------------------------------------------

async function setupHistory() {
  const first = await json(mapPath("/revisions?limit=1"));
  const slider = document.getElementById("history");
  slider.min = first.revisions.length ? first.revisions[0].id : 0;
  slider.max = state.latest ?? 0;
  slider.value = state.history ?? slider.max;
}

document.getElementById("history").addEventListener("change", async (event) => {
  const asked = Number(event.target.value);
  if (asked >= state.latest) { goLive(); return; }
  try {
    const page = await json(mapPath(`/revisions?after=${asked - 1}&limit=1`));
    const revision = page.revisions[0];
    if (!revision || revision.id >= state.latest) { goLive(); return; }
    state.history = revision.id;
    event.target.value = revision.id;
    document.getElementById("history-label").textContent = `as at revision ${revision.id}`;
    await loadAll();
    showRevision(revision);
    await showDiff(revision.id);
  } catch (error) {
    if (!(error instanceof AuthNeeded)) report(error);
  }
});

async function showDiff(from) {
  const diff = await json(mapPath(`/revisions/${from}/diff?to=${state.latest}`));
  diffLayer.clearLayers();
  const changedBins = [];
  const lines = [];
  for (const [kind, change] of Object.entries(diff.features)) {
    const keys = new Set([...change.added, ...change.removed, ...change.moved, ...change.changed].map(String));
    lines.push(`${kind}: +${change.counts.added} −${change.counts.removed} moved ${change.counts.moved}`);
    if (kind === "bin") { changedBins.push(...keys); continue; }
    const features = (state.features[kind] || []).filter((f) => keys.has(String(f.properties.key)));
    if (features.length) L.geoJSON(features, { coordsToLatLng: (c) => L.latLng(c[1], c[0]),
      style: () => ({ color: "#c000c0", weight: 4, fill: false }),
      pointToLayer: (f, at) => L.circleMarker(at, { radius: 9, color: "#c000c0", weight: 3, fill: false }),
    }).addTo(diffLayer);
  }
  for (const layer of diff.layers) lines.push(`layer ${layer.name} changed`);
  groups.bins.setChanged(changedBins);
  const info = document.getElementById("diff-info");
  info.textContent = lines.length ? `Changed since: ${lines.join("; ")}` : "Nothing changed since.";
}

function goLive() {
  state.history = null;
  diffLayer.clearLayers();
  groups.bins.setChanged([]);
  document.getElementById("history-label").textContent = "live";
  document.getElementById("diff-info").textContent = "";
  document.getElementById("history").value = state.latest;
  start();
}
document.getElementById("history-live").addEventListener("click", goLive);

// ---- asking the map ------------------------------------------------------------------------------------------

function showCard(title, rows, actions) {
  document.getElementById("card").hidden = false;
  document.getElementById("card-title").textContent = title;
  const body = document.getElementById("card-body");
  body.replaceChildren();
  for (const [name, value] of rows) {
    const row = body.insertRow();
    row.insertCell().textContent = name;
    row.insertCell().textContent = value;
    row.dataset.field = name;
  }
  const bar = document.getElementById("card-actions");
  bar.replaceChildren(...(actions || []));
}

const fmt = (v, digits = 2) => (typeof v === "number" ? v.toFixed(digits) : v ?? "–");
const pose = (p) => (p ? `(${fmt(p.x_m)}, ${fmt(p.y_m)}) ${fmt(p.yaw_rad, 2)} rad` : "–");

async function showBin(id) {
  const response = await api(atRevision(mapPath(`/bins/${encodeURIComponent(id)}`)));
  if (!response.ok) { showCard(`Bin ${id}`, [["error", await errorText(response)]]); return null; }
  const bin = await response.json();
  groups.bins.setHighlight(bin.id);
  const others = groups.bins.find(bin.id)?.spot.bins.map((f) => f.properties.key).filter((k) => k !== bin.id) || [];
  const opening = bin.opening ? `${fmt(bin.opening.width_m)} m, (${bin.opening.left.map((v) => fmt(v)).join(", ")})`
    + ` to (${bin.opening.right.map((v) => fmt(v)).join(", ")})` : "–";
  const place = (ref) => (ref ? ref.key + (ref.distance_m ? ` (${fmt(ref.distance_m, 1)} m)` : "") : "–");
  const levels = others.map((key) => {  // the bins at other levels of the same footprint
    const button = document.createElement("button");
    button.textContent = key;
    button.addEventListener("click", () => showBin(key));
    return button;
  });
  const seen = bin.occupancy;  // what the robots saw in it, when a load-scene stage runs
  const occupancy = !seen || seen.state === "unknown" ? "unknown"
    : `${seen.state} (${fmt(seen.confidence)}, ${seen.views} views`
      + `${seen.last_seen ? ", seen " + new Date(seen.last_seen).toLocaleString() : ""})`
      + (seen.objects.length ? ": " + seen.objects.join(", ") : "");
  showCard(`Bin ${bin.id}`, [["id", bin.id], ["aisle", bin.aisle ?? "–"], ["bay", bin.bay ?? "–"],
    ["level", bin.level ?? "–"], ["opening", opening], ["access pose", pose(bin.access_pose)],
    ["confidence", fmt(bin.confidence)], ["occupancy", occupancy], ["corridor", place(bin.corridor)],
    ["nearest junction", place(bin.nearest_junction)], ["revision", bin.revision_id ?? "–"]], levels);
  return bin;
}

document.getElementById("bin-search").addEventListener("submit", async (event) => {
  event.preventDefault();
  const id = document.getElementById("bin-query").value.trim();
  const message = document.getElementById("search-message");
  if (!id) return;
  const found = groups.bins.find(id);
  try {
    const bin = await showBin(id);
    if (!bin) { message.textContent = `No bin ${id}`; message.className = "message error"; return; }
    message.textContent = `Bin ${bin.id}`; message.className = "message";
    const spot = found ? found.spot : null;
    const centre = spot ? [spot.cy, spot.cx] : [bin.centre[1], bin.centre[0]];
    leaflet.flyTo(centre, Math.max(leaflet.getZoom(), 5), { duration: 0.6 });
  } catch (error) {
    if (!(error instanceof AuthNeeded)) report(error);
  }
});

async function showSemantics(x, y) {
  const answer = await json(atRevision(mapPath(`/semantics?x=${x.toFixed(3)}&y=${y.toFixed(3)}`)));
  const rows = [["x, y", `${fmt(answer.x_m)}, ${fmt(answer.y_m)} m`], ["occupancy", answer.occupancy ?? "unknown"]];
  if (answer.semantic) rows.push(["semantic", `${answer.semantic.label ?? "nothing seen"}`
    + (answer.semantic.entropy !== null ? ` (entropy ${fmt(answer.semantic.entropy)})` : "")]);
  if (answer.place) rows.push(["place", `${answer.place.label} ${answer.place.region ?? ""}`]);
  for (const f of answer.features || []) rows.push([f.kind, `${f.key}${f.label ? " " + f.label : ""}`]);
  const actions = [];
  const region = answer.place && answer.place.region;
  if (region && state.history === null) {  // the region here, and the aisle it lies in, to block or open again
    const aisles = (answer.features || []).filter((f) => f.kind === "corridor" && AISLE_KEY.test(f.key));
    const offered = new Set();
    for (const key of [region, ...aisles.map((f) => f.key)]) {
      const block = state.blocks.find((b) => b.target === "region" && (b.blocked_keys[0] === key
        || (key === region && (b.regions || []).includes(region))));
      if (offered.has(block)) continue;  // the region is closed by its aisle's block: one button for it
      offered.add(block);
      actions.push(block ? unblockButton(block, `Unblock ${blockName(block)}`) : blockButton(key));
    }
  }
  showCard("At this point", rows, actions);
}

const AISLE_KEY = /^aisle-[0-9]+$/;
const blockName = (block) => {
  const [a, b] = block.blocked_keys;
  return block.target === "connection" ? `connection ${a}–${b}` : AISLE_KEY.test(a) ? a : `region ${a}`;
};

function blockButton(region) {
  const button = document.createElement("button");
  const name = AISLE_KEY.test(region) ? region : `region ${region}`;
  button.textContent = `Block ${name}`;
  button.title = `Routes avoid a blocked ${AISLE_KEY.test(region) ? "aisle" : "region"} (needs a write key)`;
  button.addEventListener("click", () => write(mapPath(`/topology/blocked/regions/${encodeURIComponent(region)}`),
    "PUT", { reason: "blocked from the viewer" }, async (response) => {
      button.textContent = response.ok ? `${name} blocked` : await errorText(response);
    }).catch(report));
  return button;
}

function placeUnder(x, y) {
  const bins = groups.bins.binsAt(x, y);
  if (bins.length) return `bin:${bins[0].properties.key}`;
  for (const kind of ["dock", "gate", "charger"]) {
    for (const f of state.features[kind] || []) {
      const c = f.geometry.type === "Point" ? f.geometry.coordinates : f.geometry.coordinates[0];
      const d = f.geometry.type === "LineString" ? distanceToLine(f.geometry.coordinates, x, y)
        : Math.hypot(c[0] - x, c[1] - y);
      if (d < 1.5) return `${kind}:${f.properties.key}`;
    }
  }
  return `point:${x.toFixed(2)},${y.toFixed(2)}`;
}

function distanceToLine(points, x, y) {
  let best = Infinity;
  for (let i = 1; i < points.length; i++) {
    const [ax, ay] = points[i - 1], [bx, by] = points[i];
    const dx = bx - ax, dy = by - ay, t = Math.max(0, Math.min(1, ((x - ax) * dx + (y - ay) * dy)
      / (dx * dx + dy * dy || 1)));
    best = Math.min(best, Math.hypot(ax + t * dx - x, ay + t * dy - y));
  }
  return best;
}

leaflet.on("click", async (event) => {
  const x = event.latlng.lng, y = event.latlng.lat;
  try {
    if (state.placePick) { state.placePick = false; await putPlace(x, y); return; }
    if (state.routePick !== null) {
      const spec = placeUnder(x, y);
      const field = document.getElementById(state.routePick === 0 ? "route-from" : "route-to");
      field.value = spec;
      state.routePick = state.routePick === 0 ? 1 : null;
      document.getElementById("route-info").textContent = state.routePick === 1 ? "Now click where to go." : "";
      if (state.routePick === null) await drawRoute();
      return;
    }
    const bins = visible.has("bins") ? groups.bins.binsAt(x, y) : [];
    if (bins.length) await showBin(bins[0].properties.key); else await showSemantics(x, y);
  } catch (error) {
    if (!(error instanceof AuthNeeded)) report(error);
  }
});

async function drawRoute() {
  const from = document.getElementById("route-from").value.trim(), to = document.getElementById("route-to").value.trim();
  const info = document.getElementById("route-info");
  routeLayer.clearLayers();
  if (!from || !to) { info.textContent = "Give both ends."; return; }
  const response = await api(atRevision(mapPath(`/routes?from=${encodeURIComponent(from)}&to=${encodeURIComponent(to)}`)));
  if (!response.ok) { info.textContent = await errorText(response); info.className = "message error"; return; }
  const route = await response.json();
  const line = route.waypoints.map((w) => [w.y_m, w.x_m]);
  L.polyline(line, { color: "#0050ff", weight: 4, opacity: 0.85, className: "aisle-route" }).addTo(routeLayer);
  L.circleMarker(line[0], { radius: 6, color: "#0050ff", fillOpacity: 1 }).addTo(routeLayer);
  L.circleMarker(line[line.length - 1], { radius: 6, color: "#0050ff", fillColor: "#fff", fillOpacity: 1 }).addTo(routeLayer);
  info.className = "message";
  info.textContent = `${route.length_m.toFixed(1)} m from ${route.start.spec} to ${route.goal.spec} through `
    + `${route.regions.length} regions`;
  window.aisleViewer.route = route;
}

document.getElementById("route-form").addEventListener("submit", (event) => {
  event.preventDefault();
  drawRoute().catch((error) => { if (!(error instanceof AuthNeeded)) report(error); });
});
document.getElementById("route-pick").addEventListener("click", () => {
  state.routePick = 0;
  state.placePick = false;
  document.getElementById("route-info").textContent = "Click where the route starts (a bin, a dock, any point).";
});
document.getElementById("route-clear").addEventListener("click", () => {
  routeLayer.clearLayers(); state.routePick = null;
  document.getElementById("route-info").textContent = "";
});

// ---- changing the map (each needs a write key) ----------------------------------------------------------------

/** ``method`` ``body`` to ``path``, then ``done(response)``; without a (write) key the page asks for one and then
 * tries again. The map redraws from the revision event the write causes. */
async function write(path, method, body, done) {
  let response;
  try {
    response = await api(path, { method, body });
  } catch (error) {
    if (error instanceof AuthNeeded) { state.retry = () => write(path, method, body, done); return; }
    throw error;
  }
  await done(response);
}

function say(id, text, error = false) {
  const element = document.getElementById(id);
  element.textContent = text;
  element.className = error ? "message error" : "message";
}

function placeForm() {
  const kind = document.getElementById("place-kind").value, key = document.getElementById("place-key").value.trim();
  return { kind, key, path: mapPath(`/places/${kind}/${encodeURIComponent(key)}`) };
}

document.getElementById("place-form").addEventListener("submit", (event) => {
  event.preventDefault();
  const { kind, key } = placeForm();
  state.placePick = true;
  state.routePick = null;
  say("place-info", `Click where ${kind} ${key} goes.`);
});

async function putPlace(x, y) {
  const { kind, key, path } = placeForm();
  const turn = Number(document.getElementById("place-heading").value || 0) * Math.PI / 180;
  const yaw = Math.atan2(Math.sin(turn), Math.cos(turn));
  const at = [Number(x.toFixed(3)), Number(y.toFixed(3))];
  const body = { geometry: { type: "Point", coordinates: at }, approach_pose: { x_m: at[0], y_m: at[1], yaw_rad: yaw } };
  const name = document.getElementById("place-name").value.trim();
  if (name) body.name = name;
  await write(path, "PUT", body, async (response) => {
    if (!response.ok) { say("place-info", await errorText(response), true); return; }
    const place = await response.json();
    say("place-info", `${kind} ${key} ${response.status === 201 ? "set" : "moved"} at (${fmt(at[0])}, `
      + `${fmt(at[1])}), revision ${place.revision_id}`);
  });
}

document.getElementById("place-remove").addEventListener("click", () => {
  const { kind, key, path } = placeForm();
  if (!key) { say("place-info", "Give the key of the place to remove.", true); return; }
  write(path, "DELETE", undefined, async (response) => {
    say("place-info", response.ok ? `${kind} ${key} removed` : await errorText(response), !response.ok);
  }).catch(report);
});

async function drawBlocks() {
  const response = await api(atRevision(mapPath("/topology/blocked")));
  state.blocks = response.ok ? (await response.json()).blocks : [];
  const list = document.getElementById("blocks");
  list.replaceChildren(...state.blocks.map((block) => {
    const item = document.createElement("li");
    item.dataset.block = block.blocked_keys.join("/");
    item.textContent = blockName(block) + (block.reason ? ` (${block.reason})` : "") + " ";
    if (state.history === null) item.appendChild(unblockButton(block, "Unblock"));
    return item;
  }));
  if (!state.blocks.length) list.innerHTML = "<li class=\"count\">none</li>";
}

function unblockButton(block, text) {
  const button = document.createElement("button");
  button.type = "button";
  button.textContent = text;
  button.title = "Routes may pass again (needs a write key)";
  const keys = block.blocked_keys.map(encodeURIComponent);
  const path = block.target === "region" ? `/topology/blocked/regions/${keys[0]}`
    : `/topology/blocked/connections/${keys[0]}/${keys[1]}`;
  button.addEventListener("click", () => write(mapPath(path), "DELETE", undefined, async (response) => {
    say("blocks-info", response.ok ? `${blockName(block)} unblocked` : await errorText(response), !response.ok);
  }).catch(report));
  return button;
}

async function showLabelTable() {
  const table = await json(atRevision(mapPath("/label-table")));
  const rows = table.categories.map((category) => {
    const row = document.createElement("tr");
    row.dataset.category = category.category;
    row.insertCell().textContent = `#${category.category}`;
    row.insertCell().textContent = `${fmt(category.area_m2, 0)} m²`;
    row.title = `Place category ${category.category}: ${category.regions} region${category.regions === 1 ? "" : "s"}`
      + `, ${fmt(category.area_m2, 1)} m², labelled ${category.label} now`;
    const choice = document.createElement("select");
    choice.dataset.category = category.category;
    const automatic = new Option(`automatic${category.overridden ? "" : ` (${category.label})`}`, "");
    choice.add(automatic);
    for (const label of table.labels) {
      const option = new Option(label.label, label.label);
      option.title = `${label.functionality}; opens onto ${label.connectable.join(", ") || "nothing"}`;
      choice.add(option);
    }
    choice.value = table.overrides[String(category.category)] || "";
    row.insertCell().appendChild(choice);
    return row;
  });
  document.getElementById("labels-table").replaceChildren(...rows);
  const form = document.getElementById("labels-form");
  form.hidden = false;
  form.querySelector("button").disabled = state.history !== null;
  if (!rows.length) say("labels-info", "No place categories yet (the map is not decomposed).");
  document.getElementById("labels-toggle").textContent = "Hide";
}

document.getElementById("labels-toggle").addEventListener("click", () => {
  const form = document.getElementById("labels-form");
  if (!form.hidden) {
    form.hidden = true;
    document.getElementById("labels-toggle").textContent = "Show";
    return;
  }
  showLabelTable().catch((error) => { if (!(error instanceof AuthNeeded)) report(error); });
});

document.getElementById("labels-form").addEventListener("submit", (event) => {
  event.preventDefault();
  const overrides = {};
  for (const choice of document.querySelectorAll("#labels-table select")) {
    if (choice.value) overrides[choice.dataset.category] = choice.value;
  }
  write(mapPath("/label-table"), "PUT", { overrides }, async (response) => {
    if (!response.ok) { say("labels-info", await errorText(response), true); return; }
    const accepted = await response.json();
    say("labels-info", `Saved as revision ${accepted.revision_id}; the map is re-labelled from it.`);
    await showLabelTable();
  }).catch(report);
});

// ---- measuring and exporting ------------------------------------------------------------------------------

leaflet.on("mousemove", (event) => {
  document.getElementById("cursor").textContent =
    `x ${event.latlng.lng.toFixed(2)} m, y ${event.latlng.lat.toFixed(2)} m`;
});

/** The view as it is drawn now, as a canvas: images and canvases of the map panes at their screen places. */
function viewCanvas() {
  const box = leaflet.getContainer().getBoundingClientRect();
  const out = document.createElement("canvas");
  out.width = box.width; out.height = box.height;
  const ctx = out.getContext("2d");
  ctx.fillStyle = "#e8e8e8"; ctx.fillRect(0, 0, out.width, out.height);
  ctx.imageSmoothingEnabled = false;
  const depth = (element) => Number(getComputedStyle(element.closest(".leaflet-pane")).zIndex) || 0;
  const drawn = [...leaflet.getContainer().querySelectorAll(".leaflet-pane img, .leaflet-pane canvas")];
  drawn.sort((a, b) => depth(a) - depth(b));  // as the page stacks them: by pane, then in document order
  for (const element of drawn) {
    const r = element.getBoundingClientRect();
    if (r.width && r.height) ctx.drawImage(element, r.left - box.left, r.top - box.top, r.width, r.height);
  }
  return out;
}

document.getElementById("export-png").addEventListener("click", () => {
  const link = document.createElement("a");
  link.download = `aisle-${state.map}-r${state.history ?? state.shown}.png`;
  link.href = viewCanvas().toDataURL("image/png");
  link.click();
});
window.aisleViewer.viewCanvas = viewCanvas;

document.getElementById("map-select").addEventListener("change", (event) => {
  state.map = event.target.value; state.fitted = false; state.history = null; start();
});

function report(error) {
  window.aisleViewer.errors.push(String(error));
  console.warn(error);
  setLive("down", String(error.message || error).slice(0, 80));
}

buildLegend();
start();
