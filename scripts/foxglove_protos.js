// Writes the Foxglove schemas' .proto files, as @foxglove/schemas generates them, to the folder
// given (src/m3dp/record/proto): `node scripts/foxglove_protos.js src/m3dp/record/proto`. With
// `--check`, writes nothing and fails if a committed file differs from what the package makes.
"use strict";
const fs = require("fs");
const path = require("path");
const { generateProto, foxgloveMessageSchemas, foxgloveEnumSchemas } = require("@foxglove/schemas/internal");

const args = process.argv.slice(2);
const check = args.includes("--check");
const folder = args.find((arg) => !arg.startsWith("--"));
if (!folder) {
  console.error("usage: node scripts/foxglove_protos.js FOLDER [--check]");
  process.exit(2);
}
const protoText = (name) => {
  const schema = foxgloveMessageSchemas[name];
  const enums = Object.values(foxgloveEnumSchemas).filter((e) => e.parentSchemaName === schema.name);
  return generateProto(schema, enums);
};
// The messages M3DP writes, and every Foxglove message their files import.
const wanted = ["SceneUpdate", "PointCloud", "FrameTransforms", "RawImage", "CompressedImage", "CameraCalibration"];
const needed = new Set();
const visit = (name) => {
  if (needed.has(name)) return;
  needed.add(name);
  for (const match of protoText(name).matchAll(/^import "foxglove\/(\w+)\.proto";$/gm)) visit(match[1]);
};
wanted.forEach(visit);
let differ = 0;
for (const name of [...needed].sort()) {
  const text = protoText(name);
  const file = path.join(folder, "foxglove", `${name}.proto`);
  if (check) {
    const committed = fs.existsSync(file) ? fs.readFileSync(file, "utf8") : null;
    if (committed !== text) {
      console.error(`${file}: differs from @foxglove/schemas' ${name}`);
      differ++;
    }
  } else {
    fs.mkdirSync(path.dirname(file), { recursive: true });
    fs.writeFileSync(file, text);
  }
}
if (differ) process.exit(1);
console.log(`${needed.size} Foxglove schemas ${check ? "match" : "written to"} ${folder}`);
