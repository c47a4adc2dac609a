#!/usr/bin/env node
// Command-line wrapper around the Khronos glTF-Validator (npm `gltf-validator`, a library):
//
//   node tests/scripts/gltf_validator.js FILE.glb|FILE.gltf   prints the JSON validation report,
//                                                            exit 0 when it has 0 errors, 1 otherwise
//   node tests/scripts/gltf_validator.js --version            prints the validator version (setup check)
//
// External resources (a .gltf's .bin) are loaded relative to the file. The module is looked up in
// the usual node paths, then in $GEOFIT_NPM_PREFIX and $HOME/.cache/geofit/npm (where `make setup`
// installs it), so the script works from any checkout without a wrapper on PATH.
'use strict';
const fs = require('fs');
const path = require('path');

function loadValidator() {
  const prefixes = [process.env.GEOFIT_NPM_PREFIX, path.join(process.env.HOME || '', '.cache/geofit/npm')];
  const candidates = ['gltf-validator'];
  for (const p of prefixes) {
    if (p) candidates.push(path.join(p, 'lib/node_modules/gltf-validator'));
  }
  for (const c of candidates) {
    try {
      return require(c);
    } catch (e) {
      if (e.code !== 'MODULE_NOT_FOUND') throw e;
    }
  }
  process.stderr.write('gltf_validator.js: npm package gltf-validator not found; run `make setup-npm`\n');
  process.exit(3);
}

const validator = loadValidator();
const arg = process.argv[2];
if (arg === '--version') {
  console.log(validator.version());
  process.exit(0);
}
if (!arg || process.argv.length !== 3) {
  process.stderr.write('usage: gltf_validator.js FILE.glb|FILE.gltf | --version\n');
  process.exit(2);
}
const full = path.resolve(arg);
let bytes;
try {
  bytes = fs.readFileSync(full);
} catch (e) {
  process.stderr.write(`gltf_validator.js: ${arg}: ${e.message}\n`);
  process.exit(3);
}
validator
  .validateBytes(new Uint8Array(bytes), {
    uri: path.basename(full),
    maxIssues: 0,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.resolve(path.dirname(full), decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  })
  .then((report) => {
    console.log(JSON.stringify(report, null, 2));
    process.exit(report.issues.numErrors === 0 ? 0 : 1);
  })
  .catch((e) => {
    process.stderr.write(`gltf_validator.js: ${arg}: ${e}\n`);
    process.exit(3);
  });
