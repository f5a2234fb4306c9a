// Aisle viewer: every bin of the map drawn on one canvas (thousands of bins, no DOM node each), with their
// WMS ids once zoomed in far enough to read them, and a hit test for clicks. Map metres: x right, y up;
// Leaflet CRS.Simple latlng is [y, x].
"use strict";

window.BinLayer = L.Layer.extend({
  options: { fill: "rgba(230, 140, 40, 0.35)", stroke: "#b35f00", highlight: "#d00000", changed: "#c000c0",
    labelMinPx: 26 },

  initialize(options) {
    L.setOptions(this, options);
    this._spots = [];      // one per footprint: {ring, minX, minY, maxX, maxY, cx, cy, bins: [feature...]}
    this._byId = new Map();
    this._highlight = null;
    this._changed = new Set();
  },

  setBins(features) {
    const spots = new Map();
    this._byId = new Map();
    for (const f of features) {
      const ring = outerRing(f.geometry);
      if (!ring) continue;
      const key = ring.map((p) => p[0].toFixed(2) + "," + p[1].toFixed(2)).join(";");
      let spot = spots.get(key);
      if (!spot) {
        const xs = ring.map((p) => p[0]), ys = ring.map((p) => p[1]);
        spot = { ring, minX: Math.min(...xs), maxX: Math.max(...xs), minY: Math.min(...ys), maxY: Math.max(...ys),
          bins: [] };
        spot.cx = (spot.minX + spot.maxX) / 2; spot.cy = (spot.minY + spot.maxY) / 2;
        spots.set(key, spot);
      }
      spot.bins.push(f);
      this._byId.set(String(f.properties.key), { feature: f, spot });
    }
    for (const spot of spots.values()) {
      spot.bins.sort((a, b) => (a.properties.level ?? 0) - (b.properties.level ?? 0));
    }
    this._spots = [...spots.values()];
    this.redraw();
  },

  count() { return this._byId.size; },
  ids() { return [...this._byId.keys()]; },
  find(id) { return this._byId.get(id) || null; },
  setHighlight(id) { this._highlight = id; this.redraw(); },
  setChanged(ids) { this._changed = new Set(ids); this.redraw(); },

  /** The bins whose footprint holds the point (x, y) in metres, lowest level first. */
  binsAt(x, y) {
    for (const s of this._spots) {
      if (x >= s.minX && x <= s.maxX && y >= s.minY && y <= s.maxY && inside(s.ring, x, y)) return s.bins;
    }
    return [];
  },

  onAdd(map) {
    this._canvas = L.DomUtil.create("canvas", "aisle-bins leaflet-zoom-animated");
    this._canvas.dataset.layer = "bins";
    map.getPanes().overlayPane.appendChild(this._canvas);
    map.on("moveend zoomend resize viewreset", this.redraw, this);
    map.on("zoomanim", this._animateZoom, this);
    this.redraw();
  },

  onRemove(map) {
    map.off("moveend zoomend resize viewreset", this.redraw, this);
    map.off("zoomanim", this._animateZoom, this);
    L.DomUtil.remove(this._canvas);
    this._canvas = null;
  },

  _animateZoom(e) {
    const scale = this._map.getZoomScale(e.zoom);
    const offset = this._map._latLngBoundsToNewLayerBounds(this._bounds, e.zoom, e.center).min;
    L.DomUtil.setTransform(this._canvas, offset, scale);
  },

  redraw() {
    const map = this._map, canvas = this._canvas;
    if (!map || !canvas) return;
    const size = map.getSize(), dpr = window.devicePixelRatio || 1;
    this._bounds = map.getBounds();
    L.DomUtil.setPosition(canvas, map.containerPointToLayerPoint([0, 0]));
    canvas.width = size.x * dpr; canvas.height = size.y * dpr;
    canvas.style.width = size.x + "px"; canvas.style.height = size.y + "px";
    const ctx = canvas.getContext("2d");
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    const o = map.latLngToContainerPoint([0, 0]), s = Math.pow(2, map.getZoom());
    const px = (x) => o.x + x * s, py = (y) => o.y - y * s;
    const b = this._bounds, west = b.getWest(), east = b.getEast(), south = b.getSouth(), north = b.getNorth();
    const visible = this._spots.filter((sp) => sp.maxX >= west && sp.minX <= east && sp.maxY >= south
      && sp.minY <= north);
    ctx.beginPath();
    for (const sp of visible) trace(ctx, sp.ring, px, py);
    ctx.fillStyle = this.options.fill; ctx.fill();
    ctx.lineWidth = 1; ctx.strokeStyle = this.options.stroke; ctx.stroke();
    for (const sp of visible) {
      const marked = sp.bins.find((f) => f.properties.key === this._highlight);
      const changed = sp.bins.some((f) => this._changed.has(String(f.properties.key)));
      if (!marked && !changed) continue;
      ctx.beginPath(); trace(ctx, sp.ring, px, py);
      ctx.lineWidth = 3; ctx.strokeStyle = marked ? this.options.highlight : this.options.changed; ctx.stroke();
    }
    const widthPx = (sp) => (sp.maxX - sp.minX) * s, heightPx = (sp) => (sp.maxY - sp.minY) * s;
    if (visible.length && visible.length < 3000) {
      ctx.fillStyle = "#222"; ctx.textAlign = "center"; ctx.textBaseline = "middle";
      for (const sp of visible) {
        if (widthPx(sp) < this.options.labelMinPx * 2 || heightPx(sp) < 11) continue;
        const fontPx = Math.max(8, Math.min(12, heightPx(sp) / (sp.bins.length + 0.5)));
        ctx.font = fontPx + "px sans-serif";
        const rows = heightPx(sp) >= fontPx * sp.bins.length ? sp.bins.map((f) => f.properties.key)
          : [sp.bins[0].properties.key + (sp.bins.length > 1 ? " +" + (sp.bins.length - 1) : "")];
        rows.forEach((text, i) => ctx.fillText(text, px(sp.cx), py(sp.cy) + (i - (rows.length - 1) / 2) * fontPx,
          widthPx(sp) - 2));
      }
    }
  },
});

function outerRing(geometry) {
  if (!geometry) return null;
  if (geometry.type === "Polygon") return geometry.coordinates[0];
  if (geometry.type === "MultiPolygon") return geometry.coordinates[0][0];
  if (geometry.type === "Point") {
    const [x, y] = geometry.coordinates, h = 0.3;
    return [[x - h, y - h], [x + h, y - h], [x + h, y + h], [x - h, y + h], [x - h, y - h]];
  }
  return null;
}

function trace(ctx, ring, px, py) {
  ring.forEach((p, i) => (i ? ctx.lineTo(px(p[0]), py(p[1])) : ctx.moveTo(px(p[0]), py(p[1]))));
  ctx.closePath();
}

function inside(ring, x, y) {
  let hit = false;
  for (let i = 0, j = ring.length - 1; i < ring.length; j = i++) {
    const [xi, yi] = ring[i], [xj, yj] = ring[j];
    if ((yi > y) !== (yj > y) && x < ((xj - xi) * (y - yi)) / (yj - yi) + xi) hit = !hit;
  }
  return hit;
}
