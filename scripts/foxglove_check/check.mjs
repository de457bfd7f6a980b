// Reads an MCAP log the way Foxglove does, with Foxglove's published code, and decodes every message.
//
//   node scripts/foxglove_check/check.mjs LOG.mcap   ->  one JSON report on stdout; exit 0 iff every
//                                                       channel's every message decoded
//
// * The file: @mcap/core's McapStreamReader (Foxglove's MCAP reader) with CRC validation, chunks
//   decompressed by @mcap/support's loadDecompressHandlers (zstd, lz4, bz2 as Foxglove loads them), then
//   McapIndexedReader: the summary (indexes, statistics) must be there and agree with the data.
// * protobuf channels: the schema's FileDescriptorSet through @mcap/support's
//   protobufFromBinaryDescriptor (what Foxglove's channel parser calls), the type looked up by the
//   schema's name, every message decoded and converted to a plain object.
// * json channels: every message parsed as JSON; with a jsonschema, every value of the message checked
//   against the type its schema declares (Foxglove builds its message definitions, plots and panels
//   from the schema, so a value of another type would show wrong). Foxglove's own JSON-schema parser
//   (parseJsonSchema) is not published on npm; the rules it applies to a schema are checked by
//   services/bus/foxglove.py's schema_problems over every schema the stack registers.
import { readFile } from "node:fs/promises";

import { McapIndexedReader, McapStreamReader } from "@mcap/core";
import { loadDecompressHandlers, protobufFromBinaryDescriptor } from "@mcap/support";

const MAX_ERRORS_PER_CHANNEL = 3;

/** Why `value` does not have the type `schema` declares ("" when it does); `path` names the field. */
function typeProblem(value, schema, path) {
  if (schema == undefined || typeof schema !== "object" || value == undefined) {
    return ""; // no declared type, or absent or null (an Optional, a NaN): Foxglove shows it empty
  }
  const kind = schema.type;
  if (kind === "number") return typeof value === "number" ? "" : `${path}: ${typeof value}, not a number`;
  if (kind === "integer") return Number.isInteger(value) ? "" : `${path}: ${JSON.stringify(value)} is not an integer`;
  if (kind === "boolean") return typeof value === "boolean" ? "" : `${path}: ${typeof value}, not a boolean`;
  if (kind === "string") return typeof value === "string" ? "" : `${path}: ${typeof value}, not a string`;
  if (kind === "array") {
    if (!Array.isArray(value)) return `${path}: ${typeof value}, not an array`;
    for (let i = 0; i < value.length; i++) {
      const problem = typeProblem(value[i], schema.items, `${path}[${i}]`);
      if (problem) return problem;
    }
    return "";
  }
  if (kind === "object") {
    if (typeof value !== "object" || Array.isArray(value)) return `${path}: not an object`;
    for (const [name, sub] of Object.entries(schema.properties ?? {})) {
      const problem = typeProblem(value[name], sub, path ? `${path}.${name}` : name);
      if (problem) return problem;
    }
    return "";
  }
  return `${path}: the schema declares no type Foxglove reads (${JSON.stringify(kind)})`;
}

/** A decoder of one channel's messages, or an Error saying why Foxglove could not make one. */
function decoderFor(channel, schema) {
  const text = new TextDecoder();
  if (channel.messageEncoding === "protobuf") {
    if (schema?.encoding !== "protobuf") throw new Error(`protobuf channel without a protobuf schema`);
    const type = protobufFromBinaryDescriptor(schema.data).lookupType(schema.name);
    return (data) => type.toObject(type.decode(data), { defaults: true, longs: Number });
  }
  if (channel.messageEncoding === "json") {
    if (schema != undefined && schema.encoding !== "jsonschema") {
      throw new Error(`json channel with a ${schema.encoding} schema`);
    }
    const jsonSchema = schema != undefined && schema.data.length > 0 ? JSON.parse(text.decode(schema.data)) : undefined;
    return (data) => {
      const value = JSON.parse(text.decode(data));
      const problem = typeProblem(value, jsonSchema, "");
      if (problem) throw new Error(problem);
      return value;
    };
  }
  throw new Error(`message encoding ${JSON.stringify(channel.messageEncoding)} is not one Foxglove decodes here`);
}

async function main(path) {
  const bytes = await readFile(path);
  const decompressHandlers = await loadDecompressHandlers();
  const reader = new McapStreamReader({ decompressHandlers, validateCrcs: true });
  reader.append(new Uint8Array(bytes.buffer, bytes.byteOffset, bytes.byteLength));
  const schemas = new Map();
  const channels = new Map(); // id -> {channel, decode|error, messages, decoded, errors}
  let messages = 0;
  let footer = false;
  for (let record; (record = reader.nextRecord()) != undefined; ) {
    if (record.type === "Schema") schemas.set(record.id, record);
    else if (record.type === "Channel" && !channels.has(record.id)) {
      const entry = { channel: record, messages: 0, decoded: 0, errors: [] };
      try {
        entry.decode = decoderFor(record, schemas.get(record.schemaId));
      } catch (err) {
        entry.errors.push(`channel: ${err.message}`);
      }
      channels.set(record.id, entry);
    } else if (record.type === "Message") {
      messages++;
      const entry = channels.get(record.channelId);
      if (entry == undefined) throw new Error(`message on unknown channel ${record.channelId}`);
      entry.messages++;
      if (entry.decode == undefined) continue;
      try {
        entry.decode(record.data);
        entry.decoded++;
      } catch (err) {
        if (entry.errors.length < MAX_ERRORS_PER_CHANNEL) entry.errors.push(`message ${entry.messages}: ${err.message}`);
      }
    } else if (record.type === "Footer") footer = true;
  }
  if (!reader.done()) throw new Error("the file ends inside a record (a recorder killed mid-chunk?)");

  // The summary section, as Foxglove's indexed reader (used for a local file) reads it.
  const readable = {
    size: async () => BigInt(bytes.byteLength),
    read: async (offset, length) => new Uint8Array(bytes.buffer, bytes.byteOffset + Number(offset), Number(length)),
  };
  const indexed = await McapIndexedReader.Initialize({ readable, decompressHandlers });
  const statsCount = indexed.statistics == undefined ? undefined : Number(indexed.statistics.messageCount);

  const report = [...channels.values()].map((e) => ({
    topic: e.channel.topic,
    message_encoding: e.channel.messageEncoding,
    schema: schemas.get(e.channel.schemaId)?.name ?? "",
    messages: e.messages,
    decoded: e.decoded,
    ok: e.errors.length === 0 && e.decoded === e.messages,
    errors: e.errors,
  }));
  const result = {
    file: path,
    reader: "@mcap/core McapStreamReader (CRCs validated) + McapIndexedReader",
    footer,
    summary_message_count: statsCount,
    messages,
    channels_total: report.length,
    channels_ok: report.filter((c) => c.ok).length,
    channels: report,
  };
  const ok = result.channels_ok === result.channels_total && footer && statsCount === messages;
  process.stdout.write(JSON.stringify(result, null, 1) + "\n");
  return ok ? 0 : 1;
}

if (process.argv.length !== 3) {
  process.stderr.write("usage: node scripts/foxglove_check/check.mjs LOG.mcap\n");
  process.exit(2);
}
main(process.argv[2]).then(
  (code) => process.exit(code),
  (err) => {
    process.stderr.write(`error: ${err.stack ?? err}\n`);
    process.exit(1);
  },
);
