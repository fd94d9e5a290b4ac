// Writes lidar2d's MCAP test fixtures (tests/fixtures/mcap/) with the reference MCAP writer,
// @mcap/core from the npm registry, so the reader is tested on files it did not write itself.
// Chunks are compressed by Debian's `zstd` and `lz4` command-line tools (the reference
// implementations; the lz4 tool writes the LZ4 frame format MCAP specifies), and the CDR of the
// messages is encoded here (little-endian, fields aligned to their size counted from the end of the
// 4-byte encapsulation header, as rclcpp does).
//
// The values the tests expect come from this script's inputs, written to expected.json beside the
// fixtures, not from lidar2d's reader.
//
// Usage: (cd tools/mcap-fixtures && npm ci && node make-fixtures.mjs ../../tests/fixtures/mcap)
import { McapWriter } from "@mcap/core";
import { execFileSync } from "node:child_process";
import fs from "node:fs";
import path from "node:path";

const out = process.argv[2];
if (!out) {
  console.error("usage: node make-fixtures.mjs OUT_DIR");
  process.exit(2);
}

// ---- CDR ----
class Cdr {
  constructor() {
    this.bytes = [0, 1, 0, 0]; // CDR_LE encapsulation
  }
  align(n) {
    while ((this.bytes.length - 4) % n !== 0) this.bytes.push(0);
  }
  raw(size, set) {
    this.align(size);
    const b = new DataView(new ArrayBuffer(size));
    set(b);
    for (let i = 0; i < size; ++i) this.bytes.push(b.getUint8(i));
    return this;
  }
  u32(v) { return this.raw(4, (b) => b.setUint32(0, v, true)); }
  i32(v) { return this.raw(4, (b) => b.setInt32(0, v, true)); }
  f32(v) { return this.raw(4, (b) => b.setFloat32(0, v, true)); }
  f64(v) { return this.raw(8, (b) => b.setFloat64(0, v, true)); }
  str(s) {
    const e = new TextEncoder().encode(s);
    this.u32(e.length + 1);
    for (const c of e) this.bytes.push(c);
    this.bytes.push(0);
    return this;
  }
  header(ns, frame) {
    return this.i32(Number(ns / 1000000000n)).u32(Number(ns % 1000000000n)).str(frame);
  }
  pose(x, y, z, yaw) {
    for (const v of [x, y, z, 0, 0, Math.sin(yaw / 2), Math.cos(yaw / 2)]) this.f64(v);
    return this;
  }
  data() { return Uint8Array.from(this.bytes); }
}

// ---- the recording: times in ns; the same content in every variant ----
const T0 = 1700000000n * 1000000000n;
const ms = (m) => T0 + BigInt(m) * 1000000n;
const mount = { parent: "base_link", child: "laser", x: 0.25, y: -0.1, z: 0.3, yaw: 0.5 };
const odom = [];
for (let k = 0; k <= 20; ++k) {
  const t = ms(100 * k); // 10 Hz for 2 s
  const s = k / 10;
  odom.push({ t, x: 0.5 * s, y: 0.25 * s * s, yaw: 0.3 * s - 0.2 });
}
const scans = [];
for (let k = 0; k < 8; ++k) {
  const t = ms(130 + 230 * k); // between odometry messages
  const ranges = [];
  for (let i = 0; i < 16; ++i) ranges.push(1 + 0.5 * k + 0.125 * i); // exact in float32
  if (k === 3) ranges[5] = Infinity; // no return
  scans.push({ t, ranges });
}
const scanMeta = { frame: "laser", angle_min: -1.5, angle_increment: 0.1875, range_min: 0.125, range_max: 20 };

function scanCdr(s) {
  const c = new Cdr().header(s.t, scanMeta.frame);
  for (const v of [scanMeta.angle_min, scanMeta.angle_min + 15 * scanMeta.angle_increment, scanMeta.angle_increment,
                   0, 0.1, scanMeta.range_min, scanMeta.range_max]) c.f32(v);
  c.u32(s.ranges.length);
  for (const r of s.ranges) c.f32(r);
  return c.u32(0).data(); // no intensities
}
function odomCdr(o) {
  const c = new Cdr().header(o.t, "odom").str("base_link").pose(o.x, o.y, 0, o.yaw);
  for (let i = 0; i < 36 + 6 + 36; ++i) c.f64(0); // pose covariance, twist, twist covariance
  return c.data();
}
function tfCdr(t, tfs) {
  const c = new Cdr().u32(tfs.length);
  for (const f of tfs) c.header(t, f.parent).str(f.child).pose(f.x, f.y, f.z, f.yaw);
  return c.data();
}
function twistCdr() {
  const c = new Cdr();
  for (let i = 0; i < 6; ++i) c.f64(0.5);
  return c.data();
}

// Messages in log-time order: tf_static first, then the streams interleaved.
const messages = [{ topic: "/tf_static", t: T0, data: tfCdr(T0, [mount]) }];
for (const o of odom) messages.push({ topic: "/odom", t: o.t, data: odomCdr(o) });
for (const s of scans) messages.push({ topic: "/scan", t: s.t, data: scanCdr(s) });
messages.push({ topic: "/cmd_vel", t: ms(500), data: twistCdr() });
messages.sort((a, b) => (a.t < b.t ? -1 : a.t > b.t ? 1 : 0));

const topics = {
  "/tf_static": "tf2_msgs/msg/TFMessage",
  "/odom": "nav_msgs/msg/Odometry",
  "/scan": "sensor_msgs/msg/LaserScan",
  "/cmd_vel": "geometry_msgs/msg/Twist",
};

// ---- writing ----
class FileWritable {
  constructor() { this.chunks = []; this.size = 0n; }
  async write(buf) { this.chunks.push(Buffer.from(buf)); this.size += BigInt(buf.byteLength); }
  position() { return this.size; }
  bytes() { return Buffer.concat(this.chunks); }
}

const compressors = {
  zstd: (d) => ({ compression: "zstd", compressedData: execFileSync("zstd", ["-q", "-c", "-19"], { input: d }) }),
  lz4: (d) => ({ compression: "lz4", compressedData: execFileSync("lz4", ["-q", "-c", "-9"], { input: d }) }),
};
const zstd = (d) => new Uint8Array(execFileSync("zstd", ["-q", "-c"], { input: d }));

/// One MCAP file of `msgs` with writer `options` (rosbag2's profile and channel metadata).
async function writeMcap(file, msgs, options, transform = (d) => d) {
  const w = new FileWritable();
  const writer = new McapWriter({ writable: w, ...options });
  await writer.start({ profile: "ros2", library: "lidar2d make-fixtures.mjs (@mcap/core)" });
  const ids = {};
  for (const [topic, type] of Object.entries(topics)) {
    const schemaId = await writer.registerSchema({
      name: type, encoding: "ros2msg", data: new TextEncoder().encode(`# ${type} (definition omitted)\n`),
    });
    ids[topic] = await writer.registerChannel({
      topic, schemaId, messageEncoding: "cdr", metadata: new Map([["offered_qos_profiles", ""]]),
    });
  }
  let seq = 0;
  for (const m of msgs)
    await writer.addMessage({ channelId: ids[m.topic], sequence: seq++, logTime: m.t, publishTime: m.t, data: transform(m.data) });
  await writer.end();
  fs.writeFileSync(file, w.bytes());
  return file;
}

const full = { useStatistics: true, useSummaryOffsets: true, repeatSchemas: true, repeatChannels: true,
               useChunkIndex: true, useMessageIndex: true, useAttachmentIndex: true, useMetadataIndex: true };
const bare = { useStatistics: false, useSummaryOffsets: false, repeatSchemas: false, repeatChannels: false,
               useChunkIndex: false, useMessageIndex: false, useAttachmentIndex: false, useMetadataIndex: false };

function metadataYaml(storage, files, compressionFormat, compressionMode, msgs) {
  const counts = {};
  for (const m of msgs) counts[m.topic] = (counts[m.topic] ?? 0) + 1;
  let y = "rosbag2_bagfile_information:\n  version: 5\n";
  y += `  storage_identifier: ${storage}\n  relative_file_paths:\n`;
  for (const f of files) y += `    - ${f}\n`;
  y += `  message_count: ${msgs.length}\n  topics_with_message_count:\n`;
  for (const [topic, type] of Object.entries(topics))
    y += `    - topic_metadata:\n        name: ${topic}\n        type: ${type}\n        serialization_format: cdr\n` +
         `        offered_qos_profiles: ""\n      message_count: ${counts[topic] ?? 0}\n`;
  y += `  compression_format: "${compressionFormat}"\n  compression_mode: "${compressionMode}"\n`;
  return y;
}

async function main() {
  fs.mkdirSync(out, { recursive: true });
  const at = (...p) => path.join(out, ...p);
  // Single files: every layout the spec allows for a reader that scans records in order.
  await writeMcap(at("unchunked_nosummary.mcap"), messages, { ...bare, useChunks: false });
  await writeMcap(at("unchunked.mcap"), messages, { ...full, useChunks: false });
  await writeMcap(at("chunked.mcap"), messages, { ...full, useChunks: true, chunkSize: 1024 });
  await writeMcap(at("chunked_zstd.mcap"), messages, { ...full, useChunks: true, chunkSize: 1024, compressChunk: compressors.zstd });
  await writeMcap(at("chunked_lz4.mcap"), messages, { ...full, useChunks: true, chunkSize: 1024, compressChunk: compressors.lz4 });
  await writeMcap(at("chunked_zstd_noindex.mcap"), messages,
                  { ...bare, useChunks: true, chunkSize: 1024, compressChunk: compressors.zstd });

  // rosbag2 bag folders: split over two files, then compressed by file and by message (zstd).
  const half = Math.floor(messages.length / 2);
  const parts = [messages.slice(0, half), messages.slice(half)];
  const opts = { ...full, useChunks: true, chunkSize: 4096, compressChunk: compressors.zstd };
  fs.mkdirSync(at("split"), { recursive: true });
  for (let i = 0; i < 2; ++i) await writeMcap(at("split", `split_${i}.mcap`), parts[i], opts);
  fs.writeFileSync(at("split", "metadata.yaml"), metadataYaml("mcap", ["split_0.mcap", "split_1.mcap"], "", "", messages));

  fs.mkdirSync(at("compressed_file"), { recursive: true });
  const plain = { ...full, useChunks: true, chunkSize: 4096 }; // rosbag2 compresses the whole file instead
  for (let i = 0; i < 2; ++i) {
    const tmp = await writeMcap(at("compressed_file", `c_${i}.mcap`), parts[i], plain);
    fs.writeFileSync(`${tmp}.zstd`, zstd(fs.readFileSync(tmp)));
    fs.unlinkSync(tmp);
  }
  fs.writeFileSync(at("compressed_file", "metadata.yaml"),
                   metadataYaml("mcap", ["c_0.mcap.zstd", "c_1.mcap.zstd"], "zstd", "FILE", messages));

  fs.mkdirSync(at("compressed_message"), { recursive: true });
  await writeMcap(at("compressed_message", "m_0.mcap"), messages, plain, zstd);
  fs.writeFileSync(at("compressed_message", "metadata.yaml"),
                   metadataYaml("mcap", ["m_0.mcap"], "zstd", "MESSAGE", messages));

  // What the tests compare with: this script's inputs.
  const expected = {
    note: "inputs of tools/mcap-fixtures/make-fixtures.mjs; time of a message = t0_s + offset_ns * 1e-9",
    t0_s: Number(T0 / 1000000000n),
    mount,
    scan: scanMeta,
    scans: scans.map((s) => ({ offset_ns: Number(s.t - T0), ranges: s.ranges.map((r) => (isFinite(r) ? r : "inf")) })),
    odom: odom.map((o) => ({ offset_ns: Number(o.t - T0), x: o.x, y: o.y, yaw: o.yaw })),
    message_counts: Object.fromEntries(Object.keys(topics).map((k) => [k, messages.filter((m) => m.topic === k).length])),
  };
  fs.writeFileSync(at("expected.json"), JSON.stringify(expected, null, 1) + "\n");
}

main().catch((e) => {
  console.error(e);
  process.exit(1);
});
