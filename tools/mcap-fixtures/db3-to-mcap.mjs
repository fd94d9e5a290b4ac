// Converts the messages of a rosbag2 sqlite3 bag (.db3) into an MCAP file with the reference
// writer (@mcap/core), the way rosbag2's MCAP storage lays them out (profile "ros2", one channel per
// topic, schema name = ROS type, message_encoding "cdr", log_time = the .db3 receive timestamp),
// zstd chunks compressed by Debian's `zstd` tool. The .db3 is read with python3's sqlite3 module
// (Node 20 has no sqlite), in the order rosbag2 plays it: by timestamp, then id.
//
// The test that compares both readings (test_mcap_reader, RealBagConvertedToMcapGivesTheSameFrames)
// reads the result from the build's fixture folder; the build runs this script when node and
// tools/mcap-fixtures/node_modules (`npm ci`) are present.
//
// Usage: node db3-to-mcap.mjs IN.db3 OUT.mcap
import { McapWriter } from "@mcap/core";
import { execFileSync } from "node:child_process";
import fs from "node:fs";

const [input, output] = process.argv.slice(2);
if (!input || !output) {
  console.error("usage: node db3-to-mcap.mjs IN.db3 OUT.mcap");
  process.exit(2);
}

const dump = `
import base64, json, sqlite3, sys
db = sqlite3.connect("file:" + sys.argv[1] + "?immutable=1", uri=True)
for row in db.execute("SELECT id, name, type, serialization_format FROM topics ORDER BY id"):
    print(json.dumps({"topic": row}))
for row in db.execute("SELECT topic_id, timestamp, data FROM messages ORDER BY timestamp, id"):
    print(json.dumps({"m": [row[0], str(row[1]), base64.b64encode(row[2]).decode()]}))
`;
const lines = execFileSync("/usr/bin/python3", ["-c", dump, input], { maxBuffer: 1 << 30 }).toString().split("\n");

class Writable {
  constructor() { this.parts = []; this.size = 0n; }
  async write(b) { this.parts.push(Buffer.from(b)); this.size += BigInt(b.byteLength); }
  position() { return this.size; }
}

const w = new Writable();
const writer = new McapWriter({
  writable: w,
  useChunks: true,
  chunkSize: 768 * 1024,
  compressChunk: (d) => ({ compression: "zstd", compressedData: execFileSync("zstd", ["-q", "-c"], { input: d }) }),
});
await writer.start({ profile: "ros2", library: "lidar2d db3-to-mcap.mjs (@mcap/core)" });
const channels = new Map();
let seq = 0;
for (const line of lines) {
  if (!line) continue;
  const j = JSON.parse(line);
  if (j.topic) {
    const [id, name, type, serialization] = j.topic;
    const schemaId = await writer.registerSchema({ name: type, encoding: "ros2msg", data: new Uint8Array() });
    channels.set(id, await writer.registerChannel({ topic: name, schemaId, messageEncoding: serialization, metadata: new Map() }));
  } else {
    const [topicId, t, data] = j.m;
    const time = BigInt(t);
    await writer.addMessage({ channelId: channels.get(topicId), sequence: seq++, logTime: time, publishTime: time,
                              data: Buffer.from(data, "base64") });
  }
}
await writer.end();
fs.writeFileSync(output, Buffer.concat(w.parts));
