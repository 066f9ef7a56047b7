#!/usr/bin/env node
// An independent Foxglove WebSocket client: connects with @foxglove/ws-protocol, subscribes to
// the named topics, decodes COUNT messages of each from CDR with the ros2msg schema the server
// advertised (@foxglove/rosmsg parses it, @foxglove/rosmsg2-serialization reads the bytes, as
// the Foxglove app does), and prints one JSON object on stdout:
//   {"serverInfo": {...}, "channels": {topic: {schemaName, encoding, schemaEncoding}},
//    "messages": {topic: [decoded message, ...]}, "logTimes": {topic: [ns, ...]},
//    "time": ns of the server's latest time message, or null}
// Byte arrays are printed as {"length": n, "sha256": hex}; 64-bit integers (and the times) as
// strings.
//
//   node client.js --url ws://127.0.0.1:8765 --count 5 --topic /ball_state --topic /tf_static:1 \
//       --timeout 30 [--hold 20]
//   node client.js --url ws://127.0.0.1:8765 --watch 30 --topic /ball_state --topic /tf ...
// A topic's own count follows its name after a colon (else --count). Once every topic has its
// count, the JSON is printed and the client exits 0, or with --hold stays connected (still
// subscribed) for that many seconds first. At the deadline it prints what arrived, with
// "error" saying what is missing, and exits 1; bad arguments exit 2.
// --watch S decodes every message for S seconds (or until SIGINT), then prints "received"
// (messages per topic) and, under "messages", the last one of each topic, and exits 0 (a
// viewer's load, for benchmarks/foxglove_bench.py).
"use strict";

const crypto = require("crypto");
const WebSocket = require("ws");
const { FoxgloveClient } = require("@foxglove/ws-protocol");
const { parse } = require("@foxglove/rosmsg");
const { MessageReader } = require("@foxglove/rosmsg2-serialization");

function parseArgs(argv) {
  const args = { url: "ws://127.0.0.1:8765", topics: [], count: 3, timeout: 30, hold: 0, watch: 0, counts: {} };
  for (let i = 0; i < argv.length; i += 2) {
    const [flag, value] = [argv[i], argv[i + 1]];
    if (value === undefined) throw new Error(`${flag} needs a value`);
    if (flag === "--url") args.url = value;
    else if (flag === "--topic") args.topics.push(value);
    else if (flag === "--count") args.count = Number(value);
    else if (flag === "--timeout") args.timeout = Number(value);
    else if (flag === "--hold") args.hold = Number(value);
    else if (flag === "--watch") args.watch = Number(value);
    else throw new Error(`unknown argument ${flag}`);
  }
  if (args.topics.length === 0) throw new Error("name at least one --topic");
  args.topics = args.topics.map((spec) => {
    const [topic, count] = spec.split(":");
    args.counts[topic] = count === undefined ? args.count : Number(count);
    return topic;
  });
  return args;
}

// A decoded message as plain JSON: bytes summarised, bigints as strings.
function plain(value) {
  if (value instanceof Uint8Array) {
    const sha256 = crypto.createHash("sha256").update(value).digest("hex");
    return { length: value.length, sha256 };
  }
  if (ArrayBuffer.isView(value)) return Array.from(value, plain);
  if (Array.isArray(value)) return value.map(plain);
  if (typeof value === "bigint") return value.toString();
  if (value !== null && typeof value === "object") {
    return Object.fromEntries(Object.entries(value).map(([k, v]) => [k, plain(v)]));
  }
  return value;
}

function main() {
  let args;
  try {
    args = parseArgs(process.argv.slice(2));
  } catch (error) {
    process.stderr.write(`client.js: ${error.message}\n`);
    process.exit(2);
  }
  const result = { serverInfo: null, channels: {}, messages: {}, logTimes: {}, received: {}, time: null };
  for (const topic of args.topics) {
    [result.messages[topic], result.logTimes[topic], result.received[topic]] = [[], [], 0];
  }
  const readers = new Map(); // subscription id -> {topic, reader}
  // The Foxglove SDK's server names the protocol `foxglove.sdk.v1`, the same protocol as
  // ws-protocol's `foxglove.websocket.v1` under a new name; the client leaves the choice to the
  // WebSocket, which offers both and lets the server pick.
  const client = new FoxgloveClient({
    ws: new WebSocket(args.url, ["foxglove.sdk.v1", FoxgloveClient.SUPPORTED_SUBPROTOCOL]),
  });

  let printed = false;
  const finish = (code, error) => {
    if (printed) return;
    printed = true;
    if (error) result.error = error;
    const exit = () => setTimeout(() => process.exit(code), code === 0 ? args.hold * 1000 : 0);
    process.stdout.write(`${JSON.stringify(result)}\n`, exit);
  };
  const complete = (topic) => args.watch === 0 && result.messages[topic].length >= args.counts[topic];
  if (args.watch > 0) process.on("SIGINT", () => finish(0));
  const deadline = args.watch > 0 ? setTimeout(() => finish(0), args.watch * 1000) : setTimeout(() => {
    const missing = args.topics.filter((t) => !complete(t));
    finish(1, `timed out after ${args.timeout} s waiting for messages on ${missing.join(", ")}`);
  }, args.timeout * 1000);

  client.on("error", (error) => process.stderr.write(`client.js: ${error.message || error}\n`));
  client.on("close", () => {
    clearTimeout(deadline);
    finish(1, "the server closed the connection");
  });
  client.on("serverInfo", (info) => {
    result.serverInfo = info;
  });
  client.on("time", ({ timestamp }) => {
    result.time = timestamp.toString();
  });
  client.on("advertise", (channels) => {
    for (const channel of channels) {
      if (!args.topics.includes(channel.topic) || result.channels[channel.topic]) continue;
      const { schemaName, encoding, schemaEncoding } = channel;
      result.channels[channel.topic] = { schemaName, encoding, schemaEncoding };
      if (encoding !== "cdr" || schemaEncoding !== "ros2msg") continue; // reported, not decoded
      const reader = new MessageReader(parse(channel.schema, { ros2: true }));
      readers.set(client.subscribe(channel.id), { topic: channel.topic, reader });
    }
  });
  client.on("message", ({ subscriptionId, timestamp, data }) => {
    const entry = readers.get(subscriptionId);
    if (!entry) return;
    if (complete(entry.topic)) return;
    const message = plain(entry.reader.readMessage(data));
    result.received[entry.topic] += 1;
    if (args.watch > 0) {
      [result.messages[entry.topic], result.logTimes[entry.topic]] = [[message], [timestamp.toString()]];
    } else {
      result.messages[entry.topic].push(message);
      result.logTimes[entry.topic].push(timestamp.toString());
    }
    if (args.watch === 0 && args.topics.every(complete)) {
      clearTimeout(deadline);
      finish(0);
    }
  });
}

main();
