// An independent reader of a session file, on the libraries Foxglove and Lichtblick read
// MCAP with: @mcap/core's indexed reader over @mcap/nodejs, @mcap/support's decompressors,
// ajv (JSON Schema 2020-12) and the official Foxglove schemas of @foxglove/schemas.
//
//   node read_session.mjs FILE [--dump TOPIC ...]
//
// Checks: the file opens through its index; every channel has a JSON schema and JSON
// messages; every message parses as strict JSON, holds no integer beyond 2^53 (JavaScript
// would round it), and validates against its channel's schema; every Foxglove message also
// against the official schema of its name; the transforms form one tree with a single
// root from which every frame is reachable; every scene entity is in a frame of that tree;
// on every channel the messages are in log-time order as the file holds them (read again
// record by record with @mcap/core's stream reader, the way a streaming player meets them).
// Prints a JSON summary (and the messages of the --dump topics as this reader parsed them)
// on stdout; exits 1 with the problems on stderr when a check fails.
import { open, readFile } from "node:fs/promises";

import foxgloveSchemas from "@foxglove/schemas/jsonschema.js";
import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { FileHandleReadable } from "@mcap/nodejs";
import { loadDecompressHandlers } from "@mcap/support";
import Ajv2020Module from "ajv/dist/2020.js";
import AjvModule from "ajv";

const Ajv2020 = Ajv2020Module.default ?? Ajv2020Module;
const Ajv = AjvModule.default ?? AjvModule;

const [path, ...rest] = process.argv.slice(2);
const dump = new Set(rest[0] === "--dump" ? rest.slice(1) : []);
const problems = [];
const problem = (text) => {
  if (problems.length < 50) problems.push(text);
};

const ours = new Ajv2020({ allErrors: true, allowUnionTypes: true });
ours.addKeyword("unit"); // each number's unit, an annotation keyword of our schemas
const official = new Ajv({ allErrors: true });
const validators = new Map();
const officialValidators = new Map();

function unsafeIntegers(value, where, out) {
  if (typeof value === "number" && Number.isInteger(value) && !Number.isSafeInteger(value)) {
    out.push(where);
  } else if (Array.isArray(value)) {
    value.forEach((x, i) => unsafeIntegers(x, `${where}[${i}]`, out));
  } else if (value !== null && typeof value === "object") {
    for (const [k, x] of Object.entries(value)) unsafeIntegers(x, `${where}.${k}`, out);
  }
  return out;
}

const decompressHandlers = await loadDecompressHandlers();
const handle = await open(path, "r");
const reader = await McapIndexedReader.Initialize({
  readable: new FileHandleReadable(handle),
  decompressHandlers,
});

const channels = [...reader.channelsById.values()];
for (const channel of channels) {
  const schema = reader.schemasById.get(channel.schemaId);
  if (schema === undefined) {
    problem(`${channel.topic}: no schema`);
    continue;
  }
  if (schema.encoding !== "jsonschema" || channel.messageEncoding !== "json") {
    problem(`${channel.topic}: schema ${schema.encoding}, messages ${channel.messageEncoding}`);
    continue;
  }
  if (!validators.has(schema.id)) {
    try {
      validators.set(schema.id, ours.compile(JSON.parse(new TextDecoder().decode(schema.data))));
    } catch (e) {
      problem(`${channel.topic}: schema ${schema.name} does not compile: ${e.message}`);
    }
  }
  if (schema.name.startsWith("foxglove.")) {
    const name = schema.name.slice("foxglove.".length);
    const reference = foxgloveSchemas[name];
    if (reference === undefined) {
      problem(`${channel.topic}: ${schema.name} is not an official Foxglove schema`);
    } else if (!officialValidators.has(name)) {
      officialValidators.set(name, official.compile(reference));
    }
  }
}

const counts = {};
const dumped = [];
const parents = new Map(); // child frame -> parent frame
const entityFrames = new Set();
let messages = 0;
const decoder = new TextDecoder();
for await (const message of reader.readMessages()) {
  const channel = reader.channelsById.get(message.channelId);
  const schema = reader.schemasById.get(channel.schemaId);
  const where = `${channel.topic} at ${message.logTime} ns`;
  messages += 1;
  counts[channel.topic] = (counts[channel.topic] ?? 0) + 1;
  let value;
  try {
    value = JSON.parse(decoder.decode(message.data));
  } catch (e) {
    problem(`${where}: not JSON (${e.message})`);
    continue;
  }
  for (const p of unsafeIntegers(value, "", [])) problem(`${where}: integer beyond 2^53 at ${p}`);
  const validate = validators.get(channel.schemaId);
  if (validate !== undefined && !validate(value)) {
    problem(`${where}: ${ours.errorsText(validate.errors)}`);
  }
  if (schema.name.startsWith("foxglove.")) {
    const check = officialValidators.get(schema.name.slice("foxglove.".length));
    if (check !== undefined && !check(value)) {
      problem(`${where}: not a valid ${schema.name}: ${official.errorsText(check.errors)}`);
    }
  }
  if (schema.name === "foxglove.FrameTransform") {
    const known = parents.get(value.child_frame_id);
    if (known !== undefined && known !== value.parent_frame_id) {
      problem(`${where}: frame ${value.child_frame_id} has parents ${known} and ${value.parent_frame_id}`);
    }
    parents.set(value.child_frame_id, value.parent_frame_id);
  }
  if (schema.name === "foxglove.SceneUpdate") {
    for (const entity of value.entities ?? []) entityFrames.add(entity.frame_id);
  }
  if (dump.has(channel.topic)) {
    dumped.push({ topic: channel.topic, log_time: message.logTime.toString(), message: value });
  }
}
await handle.close();

// the transform tree: one root, every frame reachable from it
const frames = new Set([...parents.keys(), ...parents.values()]);
const roots = [...frames].filter((f) => !parents.has(f));
if (roots.length !== 1) problem(`transform tree: roots ${JSON.stringify(roots)}, expected one`);
for (const frame of frames) {
  const seen = new Set();
  let f = frame;
  while (parents.has(f)) {
    if (seen.has(f)) {
      problem(`transform tree: a cycle through ${f}`);
      break;
    }
    seen.add(f);
    f = parents.get(f);
  }
  if (f !== roots[0]) problem(`transform tree: ${frame} does not reach the root ${roots[0]}`);
}
for (const frame of entityFrames) {
  if (!frames.has(frame)) problem(`scene entity in frame ${frame}, which no transform places`);
}

// log-time order per channel, in the file's own order
const outOfOrder = [];
try {
  const stream = new McapStreamReader({ decompressHandlers });
  stream.append(await readFile(path));
  const topicOf = new Map();
  const lastLog = new Map();
  for (let record = stream.nextRecord(); record !== undefined; record = stream.nextRecord()) {
    if (record.type === "Channel") {
      topicOf.set(record.id, record.topic);
    } else if (record.type === "Message") {
      const last = lastLog.get(record.channelId);
      if (last !== undefined && record.logTime < last) {
        const text = `${topicOf.get(record.channelId)}: a message logged at ${record.logTime} ns after one at ${last} ns`;
        outOfOrder.push(text);
        problem(text);
      }
      lastLog.set(record.channelId, record.logTime);
    }
  }
} catch (e) {
  problem(`stream reading: ${e.message}`);
}

const summary = {
  channels: channels.length,
  messages,
  counts,
  root: roots[0] ?? null,
  frames: [...frames].sort(),
  entity_frames: [...entityFrames].sort(),
  out_of_order: outOfOrder,
  problems,
  dumped,
};
process.stdout.write(JSON.stringify(summary) + "\n");
if (problems.length > 0) {
  for (const p of problems) process.stderr.write(p + "\n");
  process.exit(1);
}
