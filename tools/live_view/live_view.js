// probeless live view: a Foxglove WebSocket client in plain JavaScript (no build step, no
// libraries) that shows a running graph's composite and its light as a lat-long map.
//
// It speaks the subset of the Foxglove protocol it needs (docs/foxglove.md): accepts serverInfo,
// advertise, unadvertise, status and time; subscribes to two channels by topic; decodes their CDR
// (little-endian XCDR1, the foxglove_bridge's cdr encoding) for sensor_msgs/msg/Image (rgb8, bgr8,
// mono8), sensor_msgs/msg/CompressedImage (jpeg) and probeless_msgs/msg/ShLight.
//
// URL parameters: url (ws://127.0.0.1:8765), composite (/render/composite), light (/light),
// jpeg (1: the composite's "<topic>/compressed" channel instead of the raw image).
//
// The lat-long map follows docs/sh.md's picture convention (sh::LatLongDirection): camera frame
// x right, y down, z forward, up = -y; column u shows azimuth a = pi - 2 pi (u + 0.5) / W, row v
// elevation e = pi/2 - pi (v + 0.5) / H, direction (-sin a cos e, -sin e, -cos a cos e): the centre
// looks back at the camera. Radiance is the real orthonormal SH basis with the Condon-Shortley
// phase, coefficient index l (l + 1) + m (msgs::ShLight), scaled so the brightest pixel is white,
// shown with sRGB gamma.
"use strict";

const params = new URLSearchParams(window.location.search);
const config = {
  url: params.get("url") ?? "ws://127.0.0.1:8765",
  composite: params.get("composite") ?? "/render/composite",
  light: params.get("light") ?? "/light",
  jpeg: params.get("jpeg") === "1",
};

// State the page exposes for tests and for the status line.
window.liveView = { frames: 0, lights: 0, statuses: [], stamp: "", lightStamp: "", error: "",
                    connected: false };

const statusLine = document.getElementById("status");
function show() {
  const v = window.liveView;
  statusLine.textContent =
    `${config.url} ${v.connected ? "connected" : "not connected"} · composite frames ${v.frames}` +
    ` (stamp ${v.stamp || "-"}) · lights ${v.lights}` + (v.error ? ` · ${v.error}` : "") +
    (v.statuses.length ? ` · server: ${v.statuses[v.statuses.length - 1]}` : "");
}

// ---- CDR reading (little-endian; alignment counted after the 4-byte encapsulation header) ----

class CdrReader {
  constructor(bytes) {
    this.bytes = bytes;
    this.view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    if (bytes.byteLength < 4 || bytes[1] !== 0x01) throw new Error("not little-endian CDR");
    this.offset = 4;
  }
  align(n) {
    const rel = this.offset - 4;
    this.offset += (n - (rel % n)) % n;
  }
  u8() { return this.view.getUint8(this.offset++); }
  u32() { this.align(4); const v = this.view.getUint32(this.offset, true); this.offset += 4; return v; }
  i32() { this.align(4); const v = this.view.getInt32(this.offset, true); this.offset += 4; return v; }
  f32() { this.align(4); const v = this.view.getFloat32(this.offset, true); this.offset += 4; return v; }
  u64() { this.align(8); const v = this.view.getBigUint64(this.offset, true); this.offset += 8; return v; }
  string() {
    const n = this.u32();
    const s = new TextDecoder().decode(this.bytes.subarray(this.offset, this.offset + Math.max(0, n - 1)));
    this.offset += n;
    return s;
  }
  byteSequence() {
    const n = this.u32();
    if (this.offset + n > this.bytes.byteLength) throw new Error("truncated sequence");
    const v = this.bytes.subarray(this.offset, this.offset + n);
    this.offset += n;
    return v;
  }
  header() {
    const sec = this.i32();
    const nanosec = this.u32();
    return { sec, nanosec, frameId: this.string() };
  }
}

function decodeImage(bytes) {
  const r = new CdrReader(bytes);
  const header = r.header();
  const height = r.u32();
  const width = r.u32();
  const encoding = r.string();
  r.u8();  // is_bigendian
  const step = r.u32();
  return { header, width, height, encoding, step, data: r.byteSequence() };
}

function decodeCompressedImage(bytes) {
  const r = new CdrReader(bytes);
  const header = r.header();
  return { header, format: r.string(), data: r.byteSequence() };
}

function decodeShLight(bytes) {
  const r = new CdrReader(bytes);
  const header = r.header();
  r.u64();  // stamp_mono_ns
  r.u64();  // sequence
  const bands = r.u32();
  const count = r.u32();
  const coefficients = new Float32Array(count);
  for (let i = 0; i < count; i++) coefficients[i] = r.f32();
  const dominant = [r.f32(), r.f32(), r.f32()];
  return { header, bands, coefficients, dominant, intensity: r.f32(), confidence: r.f32() };
}

const stampText = (h) => `${h.sec}.${String(h.nanosec).padStart(9, "0")}`;

// ---- Drawing ----

const compositeCanvas = document.getElementById("composite");
const lightCanvas = document.getElementById("light");

async function drawComposite(message) {
  const ctx = compositeCanvas.getContext("2d");
  if (message.format !== undefined) {
    if (message.format !== "jpeg") throw new Error(`unsupported format ${message.format}`);
    const bitmap = await createImageBitmap(new Blob([message.data], { type: "image/jpeg" }));
    compositeCanvas.width = bitmap.width;
    compositeCanvas.height = bitmap.height;
    ctx.drawImage(bitmap, 0, 0);
  } else {
    const { width, height, encoding, step, data } = message;
    const channels = { rgb8: 3, bgr8: 3, mono8: 1 }[encoding];
    if (!channels) throw new Error(`unsupported image encoding ${encoding}`);
    compositeCanvas.width = width;
    compositeCanvas.height = height;
    const out = ctx.createImageData(width, height);
    for (let y = 0; y < height; y++) {
      for (let x = 0; x < width; x++) {
        const i = y * step + x * channels;
        const o = (y * width + x) * 4;
        if (channels === 1) {
          out.data[o] = out.data[o + 1] = out.data[o + 2] = data[i];
        } else if (encoding === "bgr8") {
          out.data[o] = data[i + 2]; out.data[o + 1] = data[i + 1]; out.data[o + 2] = data[i];
        } else {
          out.data[o] = data[i]; out.data[o + 1] = data[i + 1]; out.data[o + 2] = data[i + 2];
        }
        out.data[o + 3] = 255;
      }
    }
    ctx.putImageData(out, 0, 0);
  }
  window.liveView.frames++;
  window.liveView.stamp = stampText(message.header);
}

// Real orthonormal SH basis, Condon-Shortley phase, index l(l+1)+m, bands 1..5 (the recurrence
// of common/sh: Q_l^m in z, Re/Im of (x + i y)^m).
const factorial = (n) => (n <= 1 ? 1 : n * factorial(n - 1));
const kNorm = (() => {
  const k = new Float64Array(25);
  for (let l = 0; l < 5; l++) {
    for (let m = 0; m <= l; m++) {
      k[l * (l + 1) + m] = Math.sqrt(((2 * l + 1) / (4 * Math.PI)) * factorial(l - m) / factorial(l + m)) *
                           (m > 0 ? Math.SQRT2 : 1);
    }
  }
  return k;
})();

function basis(bands, x, y, z, out) {
  let c = 1, s = 0, qmm = 1;
  for (let m = 0; m < bands; m++) {
    if (m > 0) {
      const cn = c * x - s * y;
      s = c * y + s * x;
      c = cn;
      qmm *= -(2 * m - 1);
    }
    let q2 = 0, q1 = 0;
    for (let l = m; l < bands; l++) {
      let q;
      if (l === m) q = qmm;
      else if (l === m + 1) q = z * (2 * m + 1) * q1;
      else q = ((2 * l - 1) * z * q1 - (l + m - 1) * q2) / (l - m);
      const v = kNorm[l * (l + 1) + m] * q;
      if (m === 0) {
        out[l * (l + 1)] = v;
      } else {
        out[l * (l + 1) + m] = v * c;
        out[l * (l + 1) - m] = v * s;
      }
      q2 = q1;
      q1 = q;
    }
  }
}

// The direction shown by lat-long pixel (u, v) of a W x H map.
function latLongDirection(u, v, w, h) {
  const a = Math.PI - (2 * Math.PI * (u + 0.5)) / w;
  const e = Math.PI / 2 - (Math.PI * (v + 0.5)) / h;
  return [-Math.sin(a) * Math.cos(e), -Math.sin(e), -Math.cos(a) * Math.cos(e)];
}

function drawLight(light) {
  const w = lightCanvas.width, h = lightCanvas.height;
  const n = light.bands * light.bands;
  const y = new Float64Array(25);
  const radiance = new Float64Array(w * h * 3);
  let max = 0;
  for (let v = 0; v < h; v++) {
    for (let u = 0; u < w; u++) {
      const d = latLongDirection(u, v, w, h);
      basis(light.bands, d[0], d[1], d[2], y);
      for (let c = 0; c < 3; c++) {
        let sum = 0;
        for (let i = 0; i < n; i++) sum += light.coefficients[i * 3 + c] * y[i];
        radiance[(v * w + u) * 3 + c] = Math.max(0, sum);
        max = Math.max(max, sum);
      }
    }
  }
  const ctx = lightCanvas.getContext("2d");
  const out = ctx.createImageData(w, h);
  for (let p = 0; p < w * h; p++) {
    for (let c = 0; c < 3; c++) {
      const linear = max > 0 ? radiance[p * 3 + c] / max : 0;
      const srgb = linear <= 0.0031308 ? 12.92 * linear : 1.055 * Math.pow(linear, 1 / 2.4) - 0.055;
      out.data[p * 4 + c] = Math.round(255 * Math.min(1, srgb));
    }
    out.data[p * 4 + 3] = 255;
  }
  ctx.putImageData(out, 0, 0);
  window.liveView.lights++;
  window.liveView.lightStamp = stampText(light.header);
  document.getElementById("light-info").textContent =
    `${config.light}: ${light.bands} bands, confidence ${light.confidence.toFixed(2)}, ` +
    `dominant (${light.dominant.map((x) => x.toFixed(2)).join(", ")})`;
}

// ---- The Foxglove protocol ----

function connect() {
  const ws = new WebSocket(config.url, ["foxglove.websocket.v1"]);
  ws.binaryType = "arraybuffer";
  const wanted = new Map([
    [config.jpeg ? `${config.composite}/compressed` : config.composite, "composite"],
    [config.light, "light"],
  ]);
  const subscriptions = new Map();  // subscription id -> { role, schemaName }
  let nextId = 1;
  let drawing = false;  // drop composites that arrive while one is being drawn
  ws.onopen = () => { window.liveView.connected = true; show(); };
  ws.onclose = () => {
    window.liveView.connected = false;
    show();
    setTimeout(connect, 1000);
  };
  ws.onmessage = async (event) => {
    try {
      if (typeof event.data === "string") {
        const msg = JSON.parse(event.data);
        if (msg.op === "advertise") {
          const subscribe = [];
          for (const ch of msg.channels) {
            const role = wanted.get(ch.topic);
            if (!role || ch.encoding !== "cdr") continue;
            const id = nextId++;
            subscriptions.set(id, { role, schemaName: ch.schemaName, channel: ch.id });
            subscribe.push({ id, channelId: ch.id });
          }
          if (subscribe.length) ws.send(JSON.stringify({ op: "subscribe", subscriptions: subscribe }));
        } else if (msg.op === "unadvertise") {
          for (const [id, s] of subscriptions) {
            if (msg.channelIds.includes(s.channel)) subscriptions.delete(id);
          }
        } else if (msg.op === "status") {
          window.liveView.statuses.push(msg.message);
        }
        show();
        return;
      }
      const bytes = new Uint8Array(event.data);
      if (bytes[0] !== 0x01) return;  // time frames
      const view = new DataView(event.data);
      const sub = subscriptions.get(view.getUint32(1, true));
      if (!sub) return;
      const payload = bytes.subarray(13);
      if (sub.role === "light") {
        drawLight(decodeShLight(payload));
      } else if (!drawing) {
        drawing = true;
        try {
          await drawComposite(sub.schemaName === "sensor_msgs/msg/CompressedImage"
                                  ? decodeCompressedImage(payload) : decodeImage(payload));
        } finally {
          drawing = false;
        }
      }
      show();
    } catch (error) {
      window.liveView.error = String(error.message ?? error);
      show();
    }
  };
}

document.getElementById("title").textContent =
  `probeless live view: ${config.jpeg ? config.composite + "/compressed" : config.composite} and ${config.light}`;
show();
connect();
