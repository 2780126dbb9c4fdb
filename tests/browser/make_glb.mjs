// Writes the small .glb models embedded (as base64) in tests/browser/fixture.html, shaped like
// texsyn's own output: triangles with POSITION + NORMAL and either COLOR_0 vertex colours or
// TEXCOORD_0 with an embedded PNG baseColorTexture.
//
//   node tests/browser/make_glb.mjs colors|textured   prints the base64 of that model
import { deflateSync } from 'node:zlib';

/** An icosphere (subdivided twice) coloured by position. */
function colorsModel() {
  const t = (1 + Math.sqrt(5)) / 2;
  let v = [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
    [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]].map(norm);
  let f = [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
    [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
    [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]];
  for (let s = 0; s < 2; s++) {
    const mid = new Map();
    const m = (a, b) => {
      const k = a < b ? `${a},${b}` : `${b},${a}`;
      if (!mid.has(k)) { v.push(norm(v[a].map((x, i) => x + v[b][i]))); mid.set(k, v.length - 1); }
      return mid.get(k);
    };
    f = f.flatMap(([a, b, c]) => {
      const ab = m(a, b), bc = m(b, c), ca = m(c, a);
      return [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]];
    });
  }
  const colors = v.map(([x, y, z]) => [0.5 + 0.45 * x, 0.5 + 0.45 * y, 0.5 + 0.45 * z, 1]);
  return glb({ positions: v, normals: v, colors, indices: f.flat() });
}

/** A cube with a checkerboard texture. */
function texturedModel() {
  const positions = [], normals = [], uvs = [], indices = [];
  const faces = [[[1, 0, 0], [0, 0, -1], [0, 1, 0]], [[-1, 0, 0], [0, 0, 1], [0, 1, 0]],
    [[0, 1, 0], [1, 0, 0], [0, 0, -1]], [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
    [[0, 0, 1], [1, 0, 0], [0, 1, 0]], [[0, 0, -1], [-1, 0, 0], [0, 1, 0]]];
  for (const [n, u, w] of faces) {
    const base = positions.length;
    for (const [a, b] of [[-1, -1], [1, -1], [1, 1], [-1, 1]]) {
      positions.push(n.map((x, i) => 0.6 * (x + a * u[i] + b * w[i])));
      normals.push(n);
      uvs.push([(a + 1) / 2, (1 - b) / 2]);
    }
    indices.push(base, base + 1, base + 2, base, base + 2, base + 3);
  }
  const size = 16;
  const rgba = Buffer.alloc(size * size * 4);
  for (let y = 0; y < size; y++) {
    for (let x = 0; x < size; x++) {
      const dark = ((x >> 2) + (y >> 2)) % 2 === 0;
      rgba.set(dark ? [40, 90, 160, 255] : [240, 200, 60, 255], (y * size + x) * 4);
    }
  }
  return glb({ positions, normals, uvs, indices, png: png(size, size, rgba) });
}

function norm(p) {
  const l = Math.hypot(...p);
  return p.map((x) => x / l);
}

function glb({ positions, normals, colors, uvs, indices, png: image }) {
  const chunks = [];
  const bufferViews = [];
  const accessors = [];
  let offset = 0;
  const add = (buf, target) => {
    const pad = (4 - (buf.length % 4)) % 4;
    bufferViews.push({ buffer: 0, byteOffset: offset, byteLength: buf.length,
      ...(target ? { target } : {}) });
    chunks.push(buf, Buffer.alloc(pad));
    offset += buf.length + pad;
    return bufferViews.length - 1;
  };
  const floats = (rows, type) => {
    const arr = new Float32Array(rows.flat());
    const view = add(Buffer.from(arr.buffer), 34962);
    const acc = { bufferView: view, componentType: 5126, count: rows.length, type };
    if (type === 'VEC3') {
      acc.min = [0, 1, 2].map((i) => Math.min(...rows.map((r) => r[i])));
      acc.max = [0, 1, 2].map((i) => Math.max(...rows.map((r) => r[i])));
    }
    accessors.push(acc);
    return accessors.length - 1;
  };
  const attributes = { POSITION: floats(positions, 'VEC3'), NORMAL: floats(normals, 'VEC3') };
  if (colors) attributes.COLOR_0 = floats(colors, 'VEC4');
  if (uvs) attributes.TEXCOORD_0 = floats(uvs, 'VEC2');
  const idx = add(Buffer.from(new Uint32Array(indices).buffer), 34963);
  accessors.push({ bufferView: idx, componentType: 5125, count: indices.length, type: 'SCALAR' });
  const pbr = { baseColorFactor: [1, 1, 1, 1], metallicFactor: 0, roughnessFactor: 1 };
  const json = {
    asset: { version: '2.0', generator: 'texsyn tests/browser/make_glb.mjs' },
    scene: 0, scenes: [{ nodes: [0] }], nodes: [{ mesh: 0 }],
    meshes: [{ primitives: [{ attributes, indices: accessors.length - 1, material: 0, mode: 4 }] }],
    materials: [{ name: 'fixture', doubleSided: true, pbrMetallicRoughness: pbr }],
    accessors, bufferViews,
  };
  if (image) {
    json.images = [{ bufferView: add(image), mimeType: 'image/png' }];
    json.samplers = [{ magFilter: 9728, minFilter: 9728, wrapS: 33071, wrapT: 33071 }];
    json.textures = [{ sampler: 0, source: 0 }];
    pbr.baseColorTexture = { index: 0, texCoord: 0 };
  }
  json.buffers = [{ byteLength: offset }];
  let text = Buffer.from(JSON.stringify(json));
  text = Buffer.concat([text, Buffer.alloc((4 - (text.length % 4)) % 4, 0x20)]);
  const bin = Buffer.concat(chunks);
  const header = Buffer.alloc(12);
  header.write('glTF', 0);
  header.writeUInt32LE(2, 4);
  header.writeUInt32LE(12 + 8 + text.length + 8 + bin.length, 8);
  const ch = (len, type) => {
    const b = Buffer.alloc(8);
    b.writeUInt32LE(len, 0);
    b.write(type, 4);
    return b;
  };
  return Buffer.concat([header, ch(text.length, 'JSON'), text, ch(bin.length, 'BIN\0'), bin]);
}

function crc32(buf) {
  let c = ~0;
  for (const byte of buf) {
    c ^= byte;
    for (let k = 0; k < 8; k++) c = (c >>> 1) ^ (0xedb88320 & -(c & 1));
  }
  return ~c >>> 0;
}

function png(w, h, rgba) {
  const rows = [];
  for (let y = 0; y < h; y++) rows.push(Buffer.from([0]), rgba.subarray(y * w * 4, (y + 1) * w * 4));
  const chunk = (type, data) => {
    const len = Buffer.alloc(4);
    len.writeUInt32BE(data.length);
    const td = Buffer.concat([Buffer.from(type), data]);
    const crc = Buffer.alloc(4);
    crc.writeUInt32BE(crc32(td));
    return Buffer.concat([len, td, crc]);
  };
  const ihdr = Buffer.alloc(13);
  ihdr.writeUInt32BE(w, 0);
  ihdr.writeUInt32BE(h, 4);
  ihdr.set([8, 6, 0, 0, 0], 8);
  return Buffer.concat([Buffer.from([137, 80, 78, 71, 13, 10, 26, 10]), chunk('IHDR', ihdr),
    chunk('IDAT', deflateSync(Buffer.concat(rows))), chunk('IEND', Buffer.alloc(0))]);
}

const which = process.argv[2];
const model = which === 'colors' ? colorsModel() : which === 'textured' ? texturedModel() : null;
if (!model) {
  console.error('usage: node tests/browser/make_glb.mjs colors|textured');
  process.exit(2);
}
process.stdout.write(model.toString('base64').replace(/.{1,76}/g, '$&\n'));
