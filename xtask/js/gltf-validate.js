// Runs the Khronos glTF Validator (npm package `gltf-validator`, the official
// validator compiled to JavaScript) on each file named on the command line and
// prints one JSON line per file: its error and warning counts, the first error
// codes, and its extensionsRequired. Used by `cargo xtask gltf-corpus --validator DIR`
// (DIR: where `npm install gltf-validator` was run; passed as NODE_PATH).
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

async function one(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,
    externalResourceFunction: (uri) =>
      new Promise((resolve, reject) => {
        fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)), (err, data) =>
          err ? reject(err.toString()) : resolve(new Uint8Array(data)));
      }),
  });
  const messages = report.issues.messages || [];
  const codes = [...new Set(messages.filter((m) => m.severity === 0).map((m) => m.code))].slice(0, 4);
  return {
    file,
    errors: report.issues.numErrors,
    warnings: report.issues.numWarnings,
    codes,
    required: (report.info && report.info.extensionsRequired) || [],
  };
}

(async () => {
  for (const file of process.argv.slice(2)) {
    let line;
    try {
      line = await one(file);
    } catch (e) {
      line = { file, errors: -1, warnings: 0, codes: [String(e).slice(0, 200)], required: [] };
    }
    process.stdout.write(JSON.stringify(line) + '\n');
  }
})();
