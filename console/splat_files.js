// Reading what the API serves for the 3D view: the trained scene's PLY (the 3DGS "Inria"
// layout) and labels.npy (uint32 object ids per Gaussian and level, in PLY order).

const SH_C0 = 0.28209479177387814;
const PLY_TYPES = {
  float: [4, "getFloat32"], float32: [4, "getFloat32"], double: [8, "getFloat64"],
  uchar: [1, "getUint8"], uint8: [1, "getUint8"], char: [1, "getInt8"], int8: [1, "getInt8"],
  ushort: [2, "getUint16"], uint16: [2, "getUint16"], short: [2, "getInt16"], int16: [2, "getInt16"],
  uint: [4, "getUint32"], uint32: [4, "getUint32"], int: [4, "getInt32"], int32: [4, "getInt32"],
};

function plyHeader(bytes) {
  const head = new TextDecoder().decode(bytes.subarray(0, Math.min(bytes.length, 64 * 1024)));
  const end = head.indexOf("end_header\n");
  if (!head.startsWith("ply\n") || end < 0) throw new Error("not a PLY file");
  let count = 0;
  let inVertex = false;
  const properties = [];
  let stride = 0;
  for (const line of head.slice(0, end).split("\n")) {
    const words = line.trim().split(/\s+/);
    if (words[0] === "format" && words[1] !== "binary_little_endian") {
      throw new Error(`PLY format ${words[1]} is not supported (binary_little_endian only)`);
    }
    if (words[0] === "element") {
      inVertex = words[1] === "vertex";
      if (inVertex) count = Number(words[2]);
    } else if (words[0] === "property" && inVertex) {
      const type = PLY_TYPES[words[1]];
      if (!type) throw new Error(`PLY property type ${words[1]} is not supported`);
      properties.push({ name: words[2], offset: stride, type });
      stride += type[0];
    }
  }
  return { count, properties, stride, dataStart: end + "end_header\n".length };
}

const sigmoid = (value) => 1 / (1 + Math.exp(-value));

// Centres, 3D covariances, colours (SH degree 0) and opacities of every Gaussian.
export function parseSplatPly(buffer) {
  const bytes = new Uint8Array(buffer);
  const header = plyHeader(bytes);
  const view = new DataView(buffer, header.dataStart);
  if (view.byteLength < header.count * header.stride) throw new Error("the PLY file is truncated");
  const byName = Object.fromEntries(header.properties.map((property) => [property.name, property]));
  const needed = ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
    "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"];
  for (const name of needed) {
    if (!byName[name]) throw new Error(`the PLY has no ${name} property (not a Gaussian splat file)`);
  }
  const read = (index, name) => {
    const { offset, type } = byName[name];
    return view[type[1]](index * header.stride + offset, true);
  };
  const n = header.count;
  const centers = new Float32Array(n * 3);
  const covariances = new Float32Array(n * 6);
  const colors = new Float32Array(n * 4);
  for (let i = 0; i < n; i++) {
    centers.set([read(i, "x"), read(i, "y"), read(i, "z")], i * 3);
    for (let c = 0; c < 3; c++) {
      colors[i * 4 + c] = Math.min(1, Math.max(0, 0.5 + SH_C0 * read(i, `f_dc_${c}`)));
    }
    colors[i * 4 + 3] = sigmoid(read(i, "opacity"));
    const scale = [0, 1, 2].map((axis) => Math.exp(read(i, `scale_${axis}`)));
    covariances.set(covariance(scale, [0, 1, 2, 3].map((k) => read(i, `rot_${k}`))), i * 6);
  }
  return { count: n, centers, covariances, colors };
}

// Σ = R S Sᵀ Rᵀ from scales and a (w, x, y, z) quaternion, as xx, xy, xz, yy, yz, zz.
function covariance(scale, quaternion) {
  const length = Math.hypot(...quaternion) || 1;
  const [w, x, y, z] = quaternion.map((value) => value / length);
  const r = [
    1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
    2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
    2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
  ];
  const m = (row, col) => r[row * 3 + col] * scale[col];
  const entry = (a, b) => m(a, 0) * m(b, 0) + m(a, 1) * m(b, 1) + m(a, 2) * m(b, 2);
  return [entry(0, 0), entry(0, 1), entry(0, 2), entry(1, 1), entry(1, 2), entry(2, 2)];
}

// labels.npy: a uint32 array of shape [N, 3] (small, middle, large), C order.
export function parseLabels(buffer) {
  const bytes = new Uint8Array(buffer);
  if (bytes[0] !== 0x93 || String.fromCharCode(...bytes.subarray(1, 6)) !== "NUMPY") {
    throw new Error("labels.npy is not a NumPy file");
  }
  const major = bytes[6];
  const headerLength = major === 1 ? bytes[8] | (bytes[9] << 8)
    : new DataView(buffer).getUint32(8, true);
  const start = (major === 1 ? 10 : 12) + headerLength;
  const header = new TextDecoder().decode(bytes.subarray(major === 1 ? 10 : 12, start));
  if (!/u4/.test(header) || /fortran_order['"]?\s*:\s*True/.test(header)) {
    throw new Error(`labels.npy has an unexpected layout: ${header.trim()}`);
  }
  const shape = header.match(/shape['"]?\s*:\s*\(\s*(\d+)\s*,\s*(\d+)\s*,?\s*\)/);
  if (!shape || shape[2] !== "3") throw new Error(`labels.npy is not [N, 3]: ${header.trim()}`);
  const rows = Number(shape[1]);
  const copy = buffer.slice(start, start + rows * 12);
  return { rows, ids: new Uint32Array(copy) };
}

export const LEVELS = ["small", "middle", "large"];
export const NO_OBJECT = 4294967295;
