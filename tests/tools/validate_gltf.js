#!/usr/bin/env node
// Validate one .glb / .gltf file with the Khronos glTF-Validator and report the result as JSON.
//
// Setup (once, from the repository root):
//
//     npm ci --prefix tests/tools
//
// installs the pinned `gltf-validator` (see package.json / package-lock.json next to this
// script) into tests/tools/node_modules. Alternatively point NODE_PATH at a node_modules that
// already contains `gltf-validator`.
//
// Usage: node tests/tools/validate_gltf.js FILE.glb
//
// Prints one JSON object on stdout:
//     { "file", "validatorVersion", "numErrors", "numWarnings", "numInfos", "numHints",
//       "truncated", "messages": [ { "code", "severity", "pointer", "message" } ] }
// severity is spelled out ("error", "warning", "info", "hint").
//
// Exit status: 0 when numErrors == 0, 1 when the asset has errors,
//              2 on usage / IO errors or when the validator library cannot be loaded.
'use strict';

const fs = require('fs');
const path = require('path');

const SEVERITY = ['error', 'warning', 'info', 'hint'];

function fail(msg) {
  process.stderr.write(`validate_gltf: ${msg}\n`);
  process.exit(2);
}

function loadValidator() {
  // Prefer the copy pinned next to this script, then the normal resolution (which includes
  // NODE_PATH).
  const local = path.join(__dirname, 'node_modules', 'gltf-validator');
  for (const id of [local, 'gltf-validator']) {
    try {
      return require(id);
    } catch (e) {
      if (e.code !== 'MODULE_NOT_FOUND') throw e;
    }
  }
  return fail(
    'cannot load the `gltf-validator` npm package; run `npm ci --prefix tests/tools` ' +
      'from the repository root (or set NODE_PATH to a node_modules containing it)',
  );
}

async function main() {
  const args = process.argv.slice(2);
  if (args.length !== 1 || args[0] === '-h' || args[0] === '--help') {
    fail('usage: node validate_gltf.js FILE.glb');
  }
  const file = args[0];
  let bytes;
  try {
    bytes = fs.readFileSync(file);
  } catch (e) {
    fail(`cannot read ${file}: ${e.message}`);
  }

  const validator = loadValidator();
  const report = await validator.validateBytes(new Uint8Array(bytes), {
    uri: path.basename(file),
    maxIssues: 0, // unlimited
    writeTimestamp: false,
  });
  const issues = report.issues;
  const out = {
    file,
    validatorVersion: report.validatorVersion,
    numErrors: issues.numErrors,
    numWarnings: issues.numWarnings,
    numInfos: issues.numInfos,
    numHints: issues.numHints,
    truncated: issues.truncated,
    messages: issues.messages.map((m) => ({
      code: m.code,
      severity: SEVERITY[m.severity] ?? String(m.severity),
      pointer: m.pointer ?? (m.offset !== undefined ? `@byte ${m.offset}` : null),
      message: m.message,
    })),
  };
  process.stdout.write(JSON.stringify(out, null, 2) + '\n');
  process.exitCode = issues.numErrors === 0 ? 0 : 1;
}

main().catch((e) => fail(`validation failed: ${e && e.stack ? e.stack : e}`));
