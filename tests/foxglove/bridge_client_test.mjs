// foxglove_bridge against the real Foxglove client libraries: @foxglove/ws-protocol's
// FoxgloveClient (over `ws`) connects to a bridge fed by the player replaying a simulated log,
// decodes what arrives with @foxglove/rosmsg2-serialization from the advertised ros2msg schemas,
// and compares every payload byte for byte with the log's own CDR (read with @mcap/core): the
// bridge sends what the recorder writes. Then: bad client messages get error statuses on a
// connection that stays up; a stalled client drops in its own queue while the healthy client
// and the bus upstream lose nothing (its drops show as the bridge subscriber's in `probeless
// topic info`); a vanished client costs nothing.
//
//   node bridge_client_test.mjs BIN_DIR SOURCE_DIR
// Exit 0 pass, 1 fail, 77 skipped (the npm packages are not installed: run tools/setup).
import { spawn, spawnSync } from "node:child_process";
import { mkdtempSync, readFileSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join, resolve } from "node:path";
import process from "node:process";

let FoxgloveClient, WebSocket, parse, MessageReader, McapStreamReader;
try {
  // CommonJS packages: their named exports may sit under `default`.
  const named = async (name, key) => {
    const m = await import(name);
    return m[key] ?? m.default[key];
  };
  FoxgloveClient = await named("@foxglove/ws-protocol", "FoxgloveClient");
  WebSocket = (await import("ws")).default;
  parse = await named("@foxglove/rosmsg", "parse");
  MessageReader = await named("@foxglove/rosmsg2-serialization", "MessageReader");
  McapStreamReader = await named("@mcap/core", "McapStreamReader");
} catch (error) {
  console.log(`SKIPPED: the test's npm packages are missing (${error.code ?? error.message}); ` +
              "tools/setup installs them (npm ci in tests/foxglove)");
  process.exit(77);
}

const [bin, source] = process.argv.slice(2).map((p) => resolve(p));
if (!bin || !source) {
  console.error("usage: bridge_client_test.mjs BIN_DIR SOURCE_DIR");
  process.exit(2);
}
const dir = mkdtempSync(join(tmpdir(), "probeless_foxglove_"));
const children = [];
let failures = 0;

function check(condition, what) {
  if (condition) {
    console.log(`ok: ${what}`);
  } else {
    console.log(`FAILED: ${what}`);
    failures++;
  }
}

const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));

// Polls `predicate` every 20 ms until true or `ms` passed; returns its last value.
async function waitFor(predicate, ms) {
  const end = Date.now() + ms;
  while (Date.now() < end) {
    if (predicate()) return true;
    await sleep(20);
  }
  return predicate();
}

function run(command, args) {
  const r = spawnSync(command, args, { encoding: "utf8", cwd: dir });
  if (r.status !== 0) throw new Error(`${command} ${args.join(" ")} failed: ${r.stderr}`);
  return r.stdout;
}

function start(command, args) {
  const child = spawn(command, args, { cwd: dir, stdio: ["ignore", "pipe", "pipe"] });
  child.out = "";
  child.err = "";
  child.stdout.on("data", (d) => (child.out += d));
  child.stderr.on("data", (d) => (child.err += d));
  child.exited = new Promise((resolve) => child.on("exit", (code) => resolve(code)));
  children.push(child);
  return child;
}

async function stop(child) {
  child.kill("SIGINT");
  const code = await Promise.race([child.exited, sleep(10000).then(() => "timeout")]);
  if (code === "timeout") child.kill("SIGKILL");
  return code;
}

// The stamp of a decoded message's header as one BigInt of nanoseconds.
const stampOf = (m) => BigInt(m.header.stamp.sec) * 1000000000n + BigInt(m.header.stamp.nanosec);

// --- The log: a simulated 640x480 RGB-D + ground truth stream, then without chunk compression
// so that @mcap/core reads it without a decompressor.
run(`${bin}/sim`, [`${source}/data/scenarios/face_orbit.yaml`, "--out", "sim.mcap", "--frames", "30"]);
run(`${bin}/probeless`, ["bag", "convert", "sim.mcap", "log.mcap", "--compression", "none"]);
const logged = new Map(); // topic -> Map(stamp -> Uint8Array of CDR)
{
  const reader = new McapStreamReader();
  reader.append(readFileSync(join(dir, "log.mcap")));
  const schemas = new Map();
  const channels = new Map();
  for (let record; (record = reader.nextRecord()) !== undefined;) {
    if (record.type === "Schema") schemas.set(record.id, record);
    if (record.type === "Channel") {
      const schema = schemas.get(record.schemaId);
      const text = new TextDecoder().decode(schema.data);
      channels.set(record.id, { topic: record.topic, reader: new MessageReader(parse(text, { ros2: true })) });
      if (!logged.has(record.topic)) logged.set(record.topic, new Map());  // repeated per chunk
    }
    if (record.type === "Message") {
      const c = channels.get(record.channelId);
      logged.get(c.topic).set(stampOf(c.reader.readMessage(record.data)), record.data);
    }
  }
}
check(logged.get("/camera/image")?.size === 30,
      `the log has 30 images of distinct stamps (${logged.get("/camera/image")?.size})`);

// --- The graph: the player loops the log, the bridge serves it.
const player = start(`${bin}/player`, ["log.mcap", "--loop", "--no-keyboard"]);
const bridge = start(`${bin}/foxglove_bridge`, [
  "--ros-args", "-p", "port:=0", "-p", "topic_regex:=^/(camera|groundtruth)/",
  "-p", "stats_period_s:=1", "-p", "bus_queue_depth:=64", "-p", "client_queue_depth:=2",
  "-p", "send_buffer_mb:=1"]);

async function main() {
  await waitFor(() => /listening on ws:\/\/127\.0\.0\.1:(\d+)/.test(bridge.err), 10000);
  const port = Number(/listening on ws:\/\/127\.0\.0\.1:(\d+)/.exec(bridge.err)?.[1]);
  check(port > 0, `the bridge listens on 127.0.0.1 (port ${port})`);

  // A client: FoxgloveClient on ws, with everything it receives recorded.
  function connect(protocols = [FoxgloveClient.SUPPORTED_SUBPROTOCOL], to = port) {
    const ws = new WebSocket(`ws://127.0.0.1:${to}`, protocols);
    const client = new FoxgloveClient({ ws });
    const c = { ws, client, channels: new Map(), byId: new Map(), statuses: [], params: [],
                times: [], messages: new Map(), info: null, closed: false };
    client.on("serverInfo", (i) => (c.info = i));
    client.on("advertise", (list) => {
      for (const ch of list) {
        ch.reader = new MessageReader(parse(ch.schema, { ros2: true }));
        c.channels.set(ch.topic, ch);
        c.byId.set(ch.id, ch);
      }
    });
    client.on("status", (s) => c.statuses.push(s));
    client.on("parameterValues", (p) => c.params.push(p));
    client.on("time", (t) => c.times.push(t.timestamp));
    client.on("close", () => (c.closed = true));
    client.on("error", () => {});
    c.subs = new Map(); // subscription id -> topic
    c.subscribe = (topic) => {
      const id = client.subscribe(c.channels.get(topic).id);
      c.subs.set(id, topic);
      c.messages.set(topic, []);
    };
    client.on("message", (m) => {
      const topic = c.subs.get(m.subscriptionId);
      if (topic === undefined) return;
      const data = new Uint8Array(m.data.buffer, m.data.byteOffset, m.data.byteLength);
      c.messages.get(topic).push({ data: Uint8Array.from(data), timestamp: m.timestamp });
    });
    return c;
  }
  const count = (c, topic) => c.messages.get(topic)?.length ?? 0;

  // --- serverInfo, advertise
  const a = connect();
  const wanted = ["/camera/image", "/camera/image/compressed", "/camera/camera_info",
                  "/groundtruth/light", "/camera/depth"];
  await waitFor(() => a.info && wanted.every((t) => a.channels.has(t)), 10000);
  check(a.ws.protocol === "foxglove.websocket.v1", `subprotocol ${a.ws.protocol}`);
  check(a.info?.capabilities.includes("time") && a.info?.capabilities.includes("parameters"),
        "serverInfo announces time and parameters");
  check(wanted.every((t) => a.channels.has(t)), `advertised ${wanted.join(", ")}`);
  check(!a.channels.has("/clock"), "/clock (no ROS 2 type) is not advertised");
  const image = a.channels.get("/camera/image");
  check(image?.encoding === "cdr" && image?.schemaEncoding === "ros2msg" &&
        image?.schemaName === "sensor_msgs/msg/Image", "image channel: cdr, ros2msg, sensor_msgs/msg/Image");
  check(a.channels.get("/groundtruth/light")?.schemaName === "probeless_msgs/msg/ShLight",
        "light channel: probeless_msgs/msg/ShLight");
  check(a.channels.get("/camera/image/compressed")?.schemaName === "sensor_msgs/msg/CompressedImage",
        "JPEG channel: sensor_msgs/msg/CompressedImage");

  // --- Streams: decoded, and byte for byte the log's CDR.
  for (const t of ["/camera/image", "/camera/image/compressed", "/camera/camera_info", "/groundtruth/light"]) {
    a.subscribe(t);
  }
  await waitFor(() => count(a, "/camera/image") >= 15 && count(a, "/groundtruth/light") >= 15 &&
                      count(a, "/camera/image/compressed") >= 5 && count(a, "/camera/camera_info") >= 5, 30000);
  for (const t of ["/camera/image", "/groundtruth/light", "/camera/camera_info"]) {
    const got = a.messages.get(t);
    const reader = a.channels.get(t).reader;
    let same = 0;
    for (const m of got) {
      const expected = logged.get(t).get(stampOf(reader.readMessage(m.data)));
      if (expected && Buffer.compare(Buffer.from(expected), Buffer.from(m.data)) === 0) same++;
    }
    check(got.length >= 5 && same === got.length,
          `${t}: ${same} of ${got.length} messages are the log's CDR bytes exactly`);
  }
  const images = a.messages.get("/camera/image").map((m) => image.reader.readMessage(m.data));
  const info = image && a.channels.get("/camera/camera_info").reader.readMessage(a.messages.get("/camera/camera_info")[0].data);
  const im = images[0];
  check(im.width === 640 && im.height === 480 && im.encoding === "rgb8" && im.step === 1920 &&
        im.data.length === 1920 * 480, `image ${im.width}x${im.height} ${im.encoding} step ${im.step}, ${im.data.length} bytes`);
  check(info.width === im.width && info.height === im.height, "camera info matches the image size");
  const logStamps = new Set(logged.get("/camera/image").keys());
  check(images.every((m) => logStamps.has(stampOf(m))), "every image stamp is a logged stamp");
  const lights = a.messages.get("/groundtruth/light").map((m) => a.channels.get("/groundtruth/light").reader.readMessage(m.data));
  check(lights.length > 0 && lights.every((l) => l.bands >= 1 && l.bands <= 5 && l.coefficients.length > 0),
        `light decodes (bands ${lights[0]?.bands}, ${lights[0]?.coefficients.length} coefficients)`);
  const imageStamps = new Set(images.map(stampOf));
  check(lights.some((l) => imageStamps.has(stampOf(l))), "lights share the images' stamps");
  const jpegChannel = a.channels.get("/camera/image/compressed");
  const jpegs = a.messages.get("/camera/image/compressed").map((m) => jpegChannel.reader.readMessage(m.data));
  const j = jpegs[0];
  // The JPEG's own size, from its SOF0 marker.
  let sof = -1;
  for (let i = 2; i + 9 < j.data.length; i++) if (j.data[i] === 0xff && j.data[i + 1] === 0xc0) { sof = i; break; }
  const jh = sof > 0 ? (j.data[sof + 5] << 8) | j.data[sof + 6] : 0;
  const jw = sof > 0 ? (j.data[sof + 7] << 8) | j.data[sof + 8] : 0;
  check(j.format === "jpeg" && j.data[0] === 0xff && j.data[1] === 0xd8 && jw === 640 && jh === 480 &&
        j.data.length < 921600 / 4, `compressed: ${j.format}, ${jw}x${jh}, ${j.data.length} bytes`);
  check(jpegs.every((c) => logStamps.has(stampOf(c))), "every compressed image carries a logged stamp");
  const now = BigInt(Date.now()) * 1000000n;
  const rx = a.messages.get("/camera/image").map((m) => m.timestamp);
  check(rx.every((t, i) => (i === 0 || t >= rx[i - 1]) && now - t < 60_000_000_000n && t <= now + 1_000_000_000n),
        "receive timestamps: wall clock, non-decreasing");
  check(a.times.length > 0 && now - a.times[a.times.length - 1] < 5_000_000_000n, `time frames (${a.times.length})`);

  // --- Parameters, read-only
  a.client.getParameters([], "p1");
  await waitFor(() => a.params.length > 0, 5000);
  const port_param = a.params[0]?.parameters.find((p) => p.name === "/foxglove_bridge.port");
  check(a.params[0]?.id === "p1" && port_param?.value === 0, "getParameters: /foxglove_bridge.port = 0");
  a.client.setParameters([{ name: "/foxglove_bridge.port", value: 1 }], "p2");

  // --- Bad client messages: error statuses, the connection stays.
  a.ws.send("{not json");
  a.ws.send(JSON.stringify({ op: "subscribe", subscriptions: [{ id: 9000, channelId: 999999 }] }));
  a.ws.send(JSON.stringify({ op: "unsubscribe", subscriptionIds: [12345] }));
  a.ws.send(Buffer.from([0xde, 0xad, 0xbe, 0xef]));
  a.ws.send(JSON.stringify({ op: "teleport" }));
  const expectedErrors = [
    "op 'setParameters' is refused: parameters are read-only on this server",
    "malformed JSON (at byte 3 of 9)",
    "subscribe: channel 999999 is not advertised",
    "unsubscribe: subscription 12345 does not exist",
    "binary message with opcode 0xde (unknown, 4 bytes) refused",
    "unknown op 'teleport'"];
  await waitFor(() => a.statuses.filter((s) => s.level === 2).length >= expectedErrors.length, 5000);
  const errors = a.statuses.filter((s) => s.level === 2).map((s) => s.message);
  check(JSON.stringify(errors) === JSON.stringify(expectedErrors), `error statuses: ${JSON.stringify(errors)}`);
  const before = count(a, "/camera/image");
  await waitFor(() => count(a, "/camera/image") >= before + 10, 10000);
  check(!a.closed && a.ws.readyState === WebSocket.OPEN && count(a, "/camera/image") >= before + 10,
        "after the bad messages the connection is up and streaming");

  // --- A stalled client: stops reading its socket for 4 s.
  const busInfo = () => {
    const text = run(`${bin}/probeless`, ["topic", "info", "/camera/image"]);
    const published = Number(/published: (\d+) messages/.exec(text)?.[1] ?? -1);
    const bridgeSub = text.split("  - node: ").find((s) => s.startsWith("/foxglove_bridge"));
    const dropped = Number(/dropped: (\d+)/.exec(bridgeSub ?? "")?.[1] ?? -1);
    return { published, dropped };
  };
  const b = connect(["foxglove.sdk.v1"]);
  await waitFor(() => b.channels.has("/camera/image"), 5000);
  check(b.ws.protocol === "foxglove.sdk.v1", "the second client speaks foxglove.sdk.v1");
  b.subscribe("/camera/image");
  await waitFor(() => count(b, "/camera/image") >= 3, 10000);
  const bus0 = busInfo();
  const a0 = count(a, "/camera/image");
  b.ws._socket.pause();
  await sleep(4000);
  const bus1 = busInfo();
  const a1 = count(a, "/camera/image");
  const published = bus1.published - bus0.published;
  // The stalled client's queue drops are drops of the bridge's subscriber (probeless topic info);
  // the bridge's own bus queue loses nothing (the exit report's bus line, below: dropped=0).
  check(bus0.dropped >= 0 && bus1.dropped > bus0.dropped,
        `the bridge's bus subscriber (probeless topic info) dropped ${bus0.dropped} -> ${bus1.dropped} over the stall`);
  check(a1 - a0 >= published * 0.5, `the healthy client got ${a1 - a0} of ${published} images published during the stall`);
  const bBefore = count(b, "/camera/image");
  b.ws._socket.resume();
  await waitFor(() => count(b, "/camera/image") > bBefore + 3 && b.statuses.some((s) => s.level === 1), 10000);
  const warning = b.statuses.find((s) => s.level === 1)?.message ?? "";
  check(/^dropped \d+ messages: this connection is slower than the subscribed streams/.test(warning),
        `the stalled client resumes and is told: "${warning}"`);
  await waitFor(() => /new drops in slow clients' queues/.test(bridge.err), 3000);
  check(/\[warn\] \[\/foxglove_bridge\] channel \d+ \/camera\/image: .* new drops in slow clients' queues/.test(bridge.err),
        "the bridge logs the client-queue drops");
  // The client-queue drops of /camera/image (all clients) as last logged; read after the log, the
  // bridge subscriber's drops in probeless topic info are at least as many.
  const dropLines = [...bridge.err.matchAll(/channel \d+ \/camera\/image: messages=\d+ bytes=\d+ dropped=(\d+)/g)];
  const clientDropped = Number(dropLines.at(-1)?.[1] ?? -1);
  const bus2 = busInfo();
  check(clientDropped > 0 && bus2.dropped >= clientDropped,
        `probeless topic info shows the bridge subscriber's drops (${bus2.dropped}) >= the clients' queue drops (${clientDropped})`);

  // --- A client that vanishes (no close handshake): the rest goes on.
  b.ws._socket.destroy();
  const a2 = count(a, "/camera/image");
  await waitFor(() => count(a, "/camera/image") >= a2 + 10, 10000);
  check(count(a, "/camera/image") >= a2 + 10, "a vanished client costs the others nothing");

  // --- A client offering no Foxglove subprotocol is refused.
  const plain = new WebSocket(`ws://127.0.0.1:${port}`, ["chat"]);
  const refused = await new Promise((resolve) => {
    plain.on("open", () => resolve(false));
    plain.on("error", () => resolve(true));
    plain.on("unexpected-response", () => resolve(true));
    setTimeout(() => resolve(false), 5000);
  });
  check(refused, "a handshake without a Foxglove subprotocol is refused");

  // A bridge on the replay's clock (clock_topic:=/clock): receive times and time frames are the
  // log's time (this simulated log starts at 0 s; looping goes on from there), far below the wall
  // clock's 1.7e18 ns.
  const clocked = start(`${bin}/foxglove_bridge`, [
    "--ros-args", "-r", "__node:=foxglove_clock", "-p", "port:=0", "-p", "clock_topic:=/clock",
    "-p", "topics:=[/groundtruth/light]", "-p", "jpeg_topics:=[]", "-p", "stats_period_s:=0"]);
  await waitFor(() => /listening on ws:\/\/127\.0\.0\.1:(\d+)/.test(clocked.err), 10000);
  const clockPort = Number(/listening on ws:\/\/127\.0\.0\.1:(\d+)/.exec(clocked.err)?.[1]);
  const k = connect(undefined, clockPort);
  await waitFor(() => k.channels.has("/groundtruth/light"), 5000);
  if (k.channels.has("/groundtruth/light")) k.subscribe("/groundtruth/light");
  await waitFor(() => count(k, "/groundtruth/light") >= 10 && k.times.length >= 3, 10000);
  const kt = (k.messages.get("/groundtruth/light") ?? []).map((m) => m.timestamp);
  check(kt.length >= 10 && kt.every((t) => t < 1_000_000_000_000n) && k.times.length >= 3 &&
        k.times.every((t) => t < 1_000_000_000_000n),
        `clock_topic:=/clock: ${kt.length} receive times and ${k.times.length} time frames on the log's clock ` +
        `(last ${Number(kt[kt.length - 1] ?? 0n) / 1e9} s)`);
  k.client.close();
  await stop(clocked);

  // A second bridge on the same port: one line, exit 2.
  const second = spawnSync(`${bin}/foxglove_bridge`, ["--ros-args", "-p", `port:=${port}`],
                           { encoding: "utf8", timeout: 10000 });
  check(second.status === 2 &&
        second.stderr.trim() === `[error] [foxglove_bridge] cannot listen on 127.0.0.1:${port}: Address already in use`,
        `a port in use: exit ${second.status}, "${second.stderr.trim()}"`);

  a.client.close();
  const code = await stop(bridge);
  check(code === 0, `the bridge exits 0 on SIGINT (${code})`);
  const busLine = /^bus \/camera\/image: received=(\d+) dropped=(\d+) errors=(\d+)$/m.exec(bridge.out);
  check(busLine && Number(busLine[1]) > 0 && busLine[2] === "0" && busLine[3] === "0",
        `exit report (the bridge's bus queue lost nothing upstream of the clients): ${busLine?.[0]}`);
  const channelLine = /^channel \d+ \/camera\/image: messages=\d+ bytes=\d+ dropped=(\d+) subscribers=\d+$/m.exec(bridge.out);
  check(channelLine && Number(channelLine[1]) > 0, `exit report: ${channelLine?.[0]}`);
}

try {
  await main();
} catch (error) {
  console.log(`FAILED: ${error.stack}`);
  failures++;
} finally {
  for (const c of children) if (c.exitCode === null) await stop(c);
  if (failures > 0) {
    console.log("--- bridge stderr ---\n" + bridge.err.split("\n").slice(-40).join("\n"));
  }
  rmSync(dir, { recursive: true, force: true });
}
console.log(failures === 0 ? "PASSED" : `${failures} FAILED`);
process.exit(failures === 0 ? 0 : 1);
