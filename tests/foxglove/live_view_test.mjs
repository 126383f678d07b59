// tools/live_view (the plain-JavaScript page) in headless Chromium against foxglove_bridge: the
// player loops a simulated log with its camera image as /render/composite and its ground-truth
// light as /light; once the page has drawn frames the player is stopped, and a screenshot of the
// page (Chrome DevTools protocol over `ws`) is compared with the log: the composite region pixel
// by pixel with the image of the stamp the page shows, and the brightest pixel of the lat-long
// light map with the light's dominant direction.
//
//   node live_view_test.mjs BIN_DIR SOURCE_DIR
// Exit 0 pass, 1 fail, 77 skipped (chromium or the npm packages are absent: run tools/setup).
import { spawn, spawnSync } from "node:child_process";
import { mkdtempSync, readFileSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import process from "node:process";
import { inflateSync } from "node:zlib";

let WebSocket, parse, MessageReader, McapStreamReader;
try {
  const named = async (name, key) => {
    const m = await import(name);
    return m[key] ?? m.default[key];
  };
  WebSocket = (await import("ws")).default;
  parse = await named("@foxglove/rosmsg", "parse");
  MessageReader = await named("@foxglove/rosmsg2-serialization", "MessageReader");
  McapStreamReader = await named("@mcap/core", "McapStreamReader");
} catch (error) {
  console.log(`SKIPPED: the test's npm packages are missing (${error.code ?? error.message}); ` +
              "tools/setup installs them (npm ci in tests/foxglove)");
  process.exit(77);
}
const chromium = ["chromium", "chromium-browser"].find(
  (c) => spawnSync("sh", ["-c", `command -v ${c}`]).status === 0);
if (!chromium) {
  console.log("SKIPPED: chromium is not installed; tools/setup installs it (Debian chromium)");
  process.exit(77);
}

const [bin, source] = process.argv.slice(2).map((p) => resolve(p));
const dir = mkdtempSync(join(tmpdir(), "probeless_live_view_"));
const children = [];
let failures = 0;
const check = (ok, what) => {
  console.log(`${ok ? "ok" : "FAILED"}: ${what}`);
  if (!ok) failures++;
};
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
async function waitFor(predicate, ms) {
  const end = Date.now() + ms;
  while (Date.now() < end) {
    if (await predicate()) return true;
    await sleep(50);
  }
  return predicate();
}
function run(command, args) {
  const r = spawnSync(command, args, { encoding: "utf8", cwd: dir });
  if (r.status !== 0) throw new Error(`${command} ${args.join(" ")} failed: ${r.stderr}`);
}
function start(command, args) {
  const child = spawn(command, args, { cwd: dir, stdio: ["ignore", "pipe", "pipe"] });
  child.err = "";
  child.stdout.on("data", () => {});
  child.stderr.on("data", (d) => (child.err += d));
  child.exited = new Promise((r) => child.on("exit", (code) => r(code)));
  children.push(child);
  return child;
}
async function stop(child) {
  if (child.exitCode !== null) return child.exitCode;
  child.kill("SIGINT");
  const code = await Promise.race([child.exited, sleep(10000).then(() => "timeout")]);
  if (code === "timeout") child.kill("SIGKILL");
  return code;
}
const stampText = (h) => `${h.stamp.sec}.${String(h.stamp.nanosec).padStart(9, "0")}`;

// The PNG of a Chrome screenshot (8-bit RGB or RGBA, not interlaced) as { width, height, rgb }.
function decodePng(png) {
  let offset = 8, width = 0, height = 0, colorType = 0;
  const idat = [];
  while (offset < png.length) {
    const length = png.readUInt32BE(offset);
    const type = png.toString("ascii", offset + 4, offset + 8);
    const data = png.subarray(offset + 8, offset + 8 + length);
    if (type === "IHDR") {
      width = data.readUInt32BE(0);
      height = data.readUInt32BE(4);
      if (data[8] !== 8 || data[12] !== 0) throw new Error("unsupported PNG");
      colorType = data[9];
    }
    if (type === "IDAT") idat.push(data);
    offset += 12 + length;
  }
  const channels = colorType === 6 ? 4 : colorType === 2 ? 3 : 0;
  if (!channels) throw new Error(`unsupported PNG colour type ${colorType}`);
  const raw = inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const pixels = Buffer.alloc(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const a = x >= channels ? pixels[y * stride + x - channels] : 0;
      const b = y > 0 ? pixels[(y - 1) * stride + x] : 0;
      const c = x >= channels && y > 0 ? pixels[(y - 1) * stride + x - channels] : 0;
      let v = line[x];
      if (filter === 1) v += a;
      else if (filter === 2) v += b;
      else if (filter === 3) v += (a + b) >> 1;
      else if (filter === 4) {
        const p = a + b - c, pa = Math.abs(p - a), pb = Math.abs(p - b), pc = Math.abs(p - c);
        v += pa <= pb && pa <= pc ? a : pb <= pc ? b : c;
      }
      pixels[y * stride + x] = v & 0xff;
    }
  }
  const rgb = Buffer.alloc(width * height * 3);
  for (let p = 0; p < width * height; p++) {
    for (let c = 0; c < 3; c++) rgb[p * 3 + c] = pixels[p * channels + c];
  }
  return { width, height, rgb };
}

async function main() {
  // The log: 8 frames of the orbiting light, read back for the comparison.
  run(`${bin}/sim`, [`${source}/data/scenarios/face_orbit.yaml`, "--out", "sim.mcap", "--frames", "8"]);
  run(`${bin}/probeless`, ["bag", "convert", "sim.mcap", "log.mcap", "--compression", "none"]);
  const images = new Map(), lights = new Map();
  {
    const reader = new McapStreamReader();
    reader.append(readFileSync(join(dir, "log.mcap")));
    const schemas = new Map(), channels = new Map();
    for (let r; (r = reader.nextRecord()) !== undefined;) {
      if (r.type === "Schema") schemas.set(r.id, new TextDecoder().decode(r.data));
      if (r.type === "Channel") {
        channels.set(r.id, { topic: r.topic, reader: new MessageReader(parse(schemas.get(r.schemaId), { ros2: true })) });
      }
      if (r.type === "Message") {
        const c = channels.get(r.channelId);
        if (c.topic === "/camera/image") {
          const m = c.reader.readMessage(r.data);
          images.set(stampText(m.header), m);
        }
        if (c.topic === "/groundtruth/light") {
          const m = c.reader.readMessage(r.data);
          lights.set(stampText(m.header), m);
        }
      }
    }
  }
  check(images.size === 8 && lights.size === 8, `the log has 8 images and lights (${images.size}, ${lights.size})`);

  const player = start(`${bin}/player`, ["log.mcap", "--loop", "--no-keyboard", "--remap",
                                         "/camera/image:=/render/composite", "--remap", "/groundtruth/light:=/light"]);
  const bridge = start(`${bin}/foxglove_bridge`, ["--ros-args", "-p", "port:=0", "-p", "stats_period_s:=0"]);
  await waitFor(() => /listening on ws:\/\/127\.0\.0\.1:(\d+)/.test(bridge.err), 10000);
  const port = Number(/listening on ws:\/\/127\.0\.0\.1:(\d+)/.exec(bridge.err)?.[1]);
  check(port > 0, `bridge on port ${port}`);

  const browser = start(chromium, ["--headless=new", "--no-sandbox", "--disable-gpu",
                                   "--remote-debugging-port=0", `--user-data-dir=${join(dir, "chrome")}`,
                                   "--window-size=1000,700", "--force-device-scale-factor=1",
                                   "--no-first-run", "--allow-file-access-from-files", "about:blank"]);
  await waitFor(() => /DevTools listening on (ws:\/\/\S+)/.test(browser.err), 30000);
  const endpoint = /DevTools listening on (ws:\/\/\S+)/.exec(browser.err)?.[1];
  if (!endpoint) throw new Error(`chromium did not start: ${browser.err.slice(-500)}`);
  const cdp = new WebSocket(endpoint);
  await new Promise((r, j) => { cdp.on("open", r); cdp.on("error", j); });
  let nextId = 1;
  const pending = new Map();
  cdp.on("message", (text) => {
    const m = JSON.parse(text);
    if (m.id && pending.has(m.id)) {
      pending.get(m.id)(m);
      pending.delete(m.id);
    }
  });
  const send = (method, params = {}, sessionId) => new Promise((resolveSend, reject) => {
    const id = nextId++;
    pending.set(id, (m) => (m.error ? reject(new Error(`${method}: ${m.error.message}`)) : resolveSend(m.result)));
    cdp.send(JSON.stringify({ id, method, params, ...(sessionId ? { sessionId } : {}) }));
  });
  const page = `file://${source}/tools/live_view/index.html?url=ws://127.0.0.1:${port}`;
  const { targetId } = await send("Target.createTarget", { url: page });
  const { sessionId } = await send("Target.attachToTarget", { targetId, flatten: true });
  await send("Emulation.setDeviceMetricsOverride",
             { width: 1000, height: 700, deviceScaleFactor: 1, mobile: false }, sessionId);
  const state = async () => {
    const r = await send("Runtime.evaluate", { expression: "JSON.stringify(window.liveView ?? null)", returnByValue: true }, sessionId);
    return JSON.parse(r.result.value ?? "null");
  };
  await waitFor(async () => { const s = await state(); return s && s.frames >= 5 && s.lights >= 5; }, 30000);
  let s = await state();
  check(s?.connected && s.frames >= 5 && s.lights >= 5 && !s.error,
        `the page connected and drew ${s?.frames} composites and ${s?.lights} lights (${s?.error || "no error"})`);

  // Freeze the stream, then photograph the page once it has drawn its last message: under load the
  // bridge and the page may still hold frames for a while after the player stops.
  await stop(player);
  const settled = async () => {
    const seen = JSON.stringify([s?.frames, s?.lights]);
    await sleep(1000);
    s = await state();
    return JSON.stringify([s?.frames, s?.lights]) === seen;
  };
  s = await state();
  check(await waitFor(settled, 20000), `the page stopped drawing (${s?.frames} composites, ${s?.lights} lights)`);
  let png;
  for (let attempt = 0; ; attempt++) {
    const before = JSON.stringify(s);
    const shot = await send("Page.captureScreenshot", { format: "png" }, sessionId);
    png = decodePng(Buffer.from(shot.data, "base64"));
    s = await state();
    if (JSON.stringify(s) === before) break;  // nothing was drawn during the screenshot
    if (attempt === 2) {
      check(false, "the page kept drawing during 3 screenshots in a row");
      break;
    }
  }
  check(png.width === 1000 && png.height === 700, `screenshot ${png.width}x${png.height}`);

  const image = images.get(s.stamp);
  check(image !== undefined, `the page shows a logged frame (stamp ${s.stamp})`);
  if (image) {
    let sum = 0, far = 0;
    for (let y = 0; y < 480; y++) {
      for (let x = 0; x < 640; x++) {
        for (let c = 0; c < 3; c++) {
          const d = Math.abs(png.rgb[(y * png.width + x) * 3 + c] - image.data[y * image.step + x * 3 + c]);
          sum += d;
          if (d > 8) far++;
        }
      }
    }
    const mae = sum / (640 * 480 * 3);
    check(mae < 1.5 && far < 640 * 480 * 3 * 0.005,
          `composite region vs the logged image: mean abs difference ${mae.toFixed(3)}, ${far} values off by > 8`);
  }

  const light = lights.get(s.lightStamp);
  check(light !== undefined, `the light map is of a logged light (stamp ${s.lightStamp})`);
  if (light) {
    // The brightest pixel of the 256x128 map at (0, 490), back to a direction.
    let best = -1, bu = 0, bv = 0, min = 255;
    for (let v = 0; v < 128; v++) {
      for (let u = 0; u < 256; u++) {
        const p = ((490 + v) * png.width + u) * 3;
        const lum = png.rgb[p] + png.rgb[p + 1] + png.rgb[p + 2];
        if (lum > best) { best = lum; bu = u; bv = v; }
        min = Math.min(min, png.rgb[p + 1]);
      }
    }
    const a = Math.PI - (2 * Math.PI * (bu + 0.5)) / 256;
    const e = Math.PI / 2 - (Math.PI * (bv + 0.5)) / 128;
    const d = [-Math.sin(a) * Math.cos(e), -Math.sin(e), -Math.cos(a) * Math.cos(e)];
    const t = light.dominant_direction;
    const angle = (Math.acos(Math.max(-1, Math.min(1, d[0] * t[0] + d[1] * t[1] + d[2] * t[2]))) * 180) / Math.PI;
    check(best > 3 * 200 && min < best / 3 && angle < 25,
          `light map: brightest pixel (${bu}, ${bv}), R+G+B ${best} (darkest green ${min}), ` +
          `${angle.toFixed(1)} deg from the light's dominant direction`);
  }
  await send("Target.closeTarget", { targetId });
  cdp.close();
}

try {
  await main();
} catch (error) {
  console.log(`FAILED: ${error.stack}`);
  failures++;
} finally {
  for (const c of children) await stop(c);
  rmSync(dir, { recursive: true, force: true });
}
console.log(failures === 0 ? "PASSED" : `${failures} FAILED`);
process.exit(failures === 0 ? 0 : 1);
