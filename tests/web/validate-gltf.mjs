#!/usr/bin/env node
// Validates glTF/GLB files with the Khronos glTF-Validator (npm gltf-validator).
//
// usage: node validate-gltf.mjs FILE.glb...
//
// Prints per file one summary line, then one indented line per error or warning
// (severity, code, JSON pointer, message). External resources are refused: a
// published GLB must be self-contained.
//
// The validator does not know EXT_meshopt_compression (it reports the info
// UNSUPPORTED_EXTENSION and then cannot see the data of compressed buffer views,
// so accessor bounds and index ranges go unchecked). So for a file that uses it
// this script also decodes every compressed buffer view with meshoptimizer's
// decoder, rebuilds the GLB without the extension and validates that too; it is
// reported on a second line as "FILE [meshopt decoded]".
//
// Exit status: 0 all clean (infos and hints allowed), 1 some file has an error
// or a warning (or could not be decoded), 2 usage or I/O error.
//
// Packages come from $CAROUSEL_WEB_MODULES, else web/node_modules, else NODE_PATH.
import fs from 'node:fs';
import {requireWeb} from './web-modules.mjs';

const SEVERITY = ['error', 'warning', 'info', 'hint'];
const MESHOPT = 'EXT_meshopt_compression';

function usage(msg) {
  if (msg) process.stderr.write(`validate-gltf: ${msg}\n`);
  process.stderr.write('usage: node validate-gltf.mjs FILE.glb...\n');
  process.exit(2);
}

const files = process.argv.slice(2);
if (files.length === 0) usage('no file given');
for (const f of files) if (f.startsWith('-')) usage(`unknown option ${f}`);

let validator;
try {
  validator = requireWeb('gltf-validator');
} catch (e) {
  process.stderr.write(`validate-gltf: ${e.message}\n`);
  process.exit(2);
}

const refuse = (uri) => Promise.reject(new Error(`external resource refused: ${uri}`));

async function validate(bytes, uri) {
  return validator.validateBytes(bytes, {
    uri,
    maxIssues: 0,
    writeTimestamp: false,
    externalResourceFunction: refuse,
  });
}

function summarize(label, report) {
  const is = report.issues;
  const counts = `${is.numErrors} errors, ${is.numWarnings} warnings, ${is.numInfos} infos, ${is.numHints} hints`;
  // Name the info/hint codes briefly so a reader sees e.g. UNSUPPORTED_EXTENSION at once.
  const minor = new Map();
  for (const m of is.messages) {
    if (m.severity >= 2) minor.set(m.code, (minor.get(m.code) || 0) + 1);
  }
  const minorText = minor.size ? ` (${[...minor].map(([c, n]) => n > 1 ? `${c} x${n}` : c).join(', ')})` : '';
  const lines = [`${label}: ${counts}${minorText}${is.truncated ? ' [truncated]' : ''}`];
  for (const m of is.messages) {
    if (m.severity <= 1) {
      lines.push(`  ${SEVERITY[m.severity]} ${m.code} at ${m.pointer ?? '(no pointer)'}: ${m.message}`);
    }
  }
  return {lines, bad: is.numErrors + is.numWarnings > 0};
}

// ---- GLB helpers ----
function parseGlb(buf) {
  if (buf.length < 20 || buf.readUInt32LE(0) !== 0x46546c67) return null;
  const jsonLen = buf.readUInt32LE(12);
  if (buf.readUInt32LE(16) !== 0x4e4f534a || 20 + jsonLen > buf.length) return null;
  const json = JSON.parse(buf.subarray(20, 20 + jsonLen).toString('utf8'));
  let bin = null;
  const binAt = 20 + jsonLen;
  if (binAt + 8 <= buf.length && buf.readUInt32LE(binAt + 4) === 0x004e4942) {
    const binLen = buf.readUInt32LE(binAt);
    bin = buf.subarray(binAt + 8, binAt + 8 + binLen);
  }
  return {json, bin};
}

function buildGlb(json, bin) {
  let js = Buffer.from(JSON.stringify(json), 'utf8');
  js = Buffer.concat([js, Buffer.alloc((4 - (js.length % 4)) % 4, 0x20)]);
  const b = Buffer.concat([bin, Buffer.alloc((4 - (bin.length % 4)) % 4)]);
  const head = Buffer.alloc(20);
  head.writeUInt32LE(0x46546c67, 0);
  head.writeUInt32LE(2, 4);
  head.writeUInt32LE(12 + 8 + js.length + 8 + b.length, 8);
  head.writeUInt32LE(js.length, 12);
  head.writeUInt32LE(0x4e4f534a, 16);
  const binHead = Buffer.alloc(8);
  binHead.writeUInt32LE(b.length, 0);
  binHead.writeUInt32LE(0x004e4942, 4);
  return new Uint8Array(Buffer.concat([head, js, binHead, b]));
}

/** Returns a GLB with every EXT_meshopt_compression buffer view decoded into the BIN chunk. */
async function decodeMeshopt(glb) {
  const mod = requireWeb('meshoptimizer/decoder.cjs');
  const MeshoptDecoder = mod.MeshoptDecoder || mod;
  await MeshoptDecoder.ready;
  const json = structuredClone(glb.json);
  const buffers = json.buffers || [];
  // Only the GLB BIN chunk (buffer 0 without uri) can be read here.
  const readBuffer = (i) => {
    if (i === 0 && buffers[0] && buffers[0].uri === undefined && glb.bin) return glb.bin;
    throw new Error(`compressed data lives in buffers[${i}], which is not the GLB BIN chunk`);
  };
  const parts = [glb.bin ? Buffer.from(glb.bin) : Buffer.alloc(0)];
  let length = parts[0].length;
  const fallback = new Set();
  (json.bufferViews || []).forEach((view, i) => {
    const ext = view.extensions && view.extensions[MESHOPT];
    if (!ext) return;
    const src = readBuffer(ext.buffer);
    const off = ext.byteOffset || 0;
    if (off + ext.byteLength > src.length) throw new Error(`bufferViews[${i}]: compressed range outside buffer`);
    const source = new Uint8Array(src.buffer, src.byteOffset + off, ext.byteLength);
    const target = new Uint8Array(ext.count * ext.byteStride);
    try {
      MeshoptDecoder.decodeGltfBuffer(target, ext.count, ext.byteStride, source, ext.mode, ext.filter);
    } catch (e) {
      throw new Error(`bufferViews[${i}]: meshopt decode failed (${e.message || e})`);
    }
    if (target.length !== view.byteLength) {
      throw new Error(`bufferViews[${i}]: decoded ${target.length} bytes, byteLength says ${view.byteLength}`);
    }
    if (view.buffer !== 0) fallback.add(view.buffer);
    const pad = (4 - (length % 4)) % 4;
    if (pad) { parts.push(Buffer.alloc(pad)); length += pad; }
    view.buffer = 0;
    view.byteOffset = length;
    parts.push(Buffer.from(target));
    length += target.length;
    delete view.extensions[MESHOPT];
    if (Object.keys(view.extensions).length === 0) delete view.extensions;
  });
  // Drop the fallback buffers no view uses any more, and renumber the rest.
  const used = new Set((json.bufferViews || []).map((v) => v.buffer));
  const keep = buffers.map((_, i) => i === 0 || used.has(i) || !fallback.has(i));
  const remap = [];
  let n = 0;
  keep.forEach((k, i) => { remap[i] = k ? n++ : -1; });
  json.buffers = buffers.filter((_, i) => keep[i]);
  for (const v of json.bufferViews || []) v.buffer = remap[v.buffer];
  const bin = Buffer.concat(parts);
  if (json.buffers[0]) json.buffers[0].byteLength = bin.length;
  for (const key of ['extensionsUsed', 'extensionsRequired']) {
    if (json[key]) {
      json[key] = json[key].filter((e) => e !== MESHOPT);
      if (json[key].length === 0) delete json[key];
    }
  }
  return buildGlb(json, bin);
}

let anyBad = false;
for (const file of files) {
  let bytes;
  try {
    bytes = fs.readFileSync(file);
  } catch (e) {
    process.stderr.write(`validate-gltf: cannot read ${file}: ${e.message}\n`);
    process.exit(2);
  }
  const out = [];
  try {
    const report = await validate(new Uint8Array(bytes), file);
    const s = summarize(file, report);
    out.push(...s.lines);
    anyBad ||= s.bad;

    const used = (report.info && report.info.extensionsUsed) || [];
    if (used.includes(MESHOPT)) {
      const label = `${file} [meshopt decoded]`;
      let decoded = null;
      try {
        const glb = parseGlb(bytes);
        if (!glb) throw new Error('not a GLB');
        decoded = await decodeMeshopt(glb);
      } catch (e) {
        out.push(`${label}: cannot decode: ${e.message}`);
        anyBad = true;
      }
      if (decoded) {
        const s2 = summarize(label, await validate(decoded, file));
        out.push(...s2.lines);
        anyBad ||= s2.bad;
      }
    }
  } catch (e) {
    // validateBytes rejects when it cannot even tell glTF from GLB.
    out.push(`${file}: validator refused the file: ${e && e.message ? e.message : e}`);
    anyBad = true;
  }
  process.stdout.write(out.join('\n') + '\n');
}
process.exit(anyBad ? 1 : 0);
