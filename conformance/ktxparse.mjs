// ktx-parse (npm), an independent KTX2 parser and serializer, for the container conformance:
//   node ktxparse.mjs read FILE...   prints "path vkFormat faceCount levels scheme" per file
//   node ktxparse.mjs write SPEC     writes the one-level cube a JSON spec describes
import { readFileSync, writeFileSync } from 'node:fs';
import { read, write, createDefaultContainer, KHR_SUPERCOMPRESSION_ZSTD, KHR_SUPERCOMPRESSION_NONE } from 'ktx-parse';

const [mode, ...args] = process.argv.slice(2);
if (mode === 'read') {
  for (const path of args) {
    const c = read(new Uint8Array(readFileSync(path)));
    console.log(`${path} ${c.vkFormat} ${c.faceCount} ${c.levels.length} ${c.supercompressionScheme}`);
  }
} else if (mode === 'write') {
  const spec = JSON.parse(readFileSync(args[0], 'utf8'));
  const c = createDefaultContainer();
  c.vkFormat = spec.vkFormat;
  c.typeSize = spec.typeSize;
  c.pixelWidth = spec.size;
  c.pixelHeight = spec.size;
  c.faceCount = 6;
  c.levelCount = 1;
  c.supercompressionScheme = spec.zstd ? KHR_SUPERCOMPRESSION_ZSTD : KHR_SUPERCOMPRESSION_NONE;
  c.levels = [{ levelData: new Uint8Array(readFileSync(spec.level)), uncompressedByteLength: spec.uncompressed }];
  writeFileSync(spec.out, write(c));
} else {
  console.error('usage: ktxparse.mjs read FILE... | write SPEC');
  process.exit(2);
}
