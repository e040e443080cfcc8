#!/usr/bin/env node
// An independent reader of ROS 2 recordings for the tests (tests/formats/bag_peer_test.cc):
// foxglove's @mcap/core (MCAP, with lz4js for lz4 chunks), sql.js (SQLite compiled to
// WebAssembly, for .db3) and @foxglove/rosmsg + @foxglove/rosmsg2-serialization (CDR decoding of
// sensor_msgs/msg/Imu from its ROS 2 definition). None is calibd's code.
//   NODE_PATH=/work/data/node/node_modules node bag_reference.js FILE
// Prints one JSON object: per Imu topic, {count, first_stamp_ns, last_stamp_ns, first_record_ns,
// last_record_ns, accel_mean [3], gyro_mean [3]} (stamps as decimal strings: they exceed 2^53).
"use strict";
const fs = require("fs");
const { McapStreamReader } = require("@mcap/core");
const lz4 = require("lz4js");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

// sensor_msgs/msg/Imu and its dependencies, as ROS 2 defines them.
const kImu = `std_msgs/Header header
geometry_msgs/Quaternion orientation
float64[9] orientation_covariance
geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance
geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Quaternion
float64 x
float64 y
float64 z
float64 w
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
`;
const imuReader = new MessageReader(parse(kImu, { ros2: true }));

const topics = {};
function add(topic, recordNs, data) {
  const m = imuReader.readMessage(data);
  const stamp = BigInt(m.header.stamp.sec) * 1000000000n + BigInt(m.header.stamp.nanosec);
  let t = topics[topic];
  if (!t) {
    t = topics[topic] = { count: 0, first_stamp_ns: stamp, first_record_ns: recordNs,
                          accel_sum: [0, 0, 0], gyro_sum: [0, 0, 0] };
  }
  t.count += 1;
  t.last_stamp_ns = stamp;
  t.last_record_ns = recordNs;
  const a = m.linear_acceleration, g = m.angular_velocity;
  [a.x, a.y, a.z].forEach((v, i) => { t.accel_sum[i] += v; });
  [g.x, g.y, g.z].forEach((v, i) => { t.gyro_sum[i] += v; });
}

function readMcap(bytes) {
  const reader = new McapStreamReader({
    decompressHandlers: { lz4: (buffer, size) => new Uint8Array(lz4.decompress(buffer, Number(size))) },
  });
  reader.append(bytes);
  const channels = {}, schemas = {};
  for (let r; (r = reader.nextRecord()) !== undefined;) {
    if (r.type === "Schema") schemas[r.id] = r.name;
    else if (r.type === "Channel") channels[r.id] = { topic: r.topic, schema: r.schemaId };
    else if (r.type === "Message") {
      const c = channels[r.channelId];
      if (c && schemas[c.schema] === "sensor_msgs/msg/Imu") add(c.topic, r.logTime, r.data);
    }
  }
  if (!reader.done()) throw new Error("MCAP: the reader did not reach the end of the file");
}

async function readDb3(bytes) {
  const SQL = await require("sql.js")();
  const db = new SQL.Database(bytes);
  const rows = db.exec("SELECT t.name, m.timestamp, m.data FROM messages m JOIN topics t " +
                       "ON m.topic_id = t.id WHERE t.type = 'sensor_msgs/msg/Imu' ORDER BY m.id");
  for (const [topic, timestamp, data] of rows.length ? rows[0].values : []) {
    add(topic, BigInt(timestamp), data);
  }
}

(async () => {
  const bytes = new Uint8Array(fs.readFileSync(process.argv[2]));
  const head = Buffer.from(bytes.subarray(0, 16)).toString("latin1");
  if (head.startsWith("\x89MCAP")) readMcap(bytes);
  else if (head.startsWith("SQLite format 3")) await readDb3(bytes);
  else throw new Error("neither MCAP nor SQLite");
  const out = {};
  for (const [topic, t] of Object.entries(topics)) {
    out[topic] = {
      count: t.count,
      first_stamp_ns: t.first_stamp_ns.toString(), last_stamp_ns: t.last_stamp_ns.toString(),
      first_record_ns: t.first_record_ns.toString(), last_record_ns: t.last_record_ns.toString(),
      accel_mean: t.accel_sum.map((s) => s / t.count), gyro_mean: t.gyro_sum.map((s) => s / t.count),
    };
  }
  process.stdout.write(JSON.stringify(out) + "\n");
})().catch((e) => { process.stderr.write(String(e && e.stack || e) + "\n"); process.exit(1); });
