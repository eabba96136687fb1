// The 3D view's camera: a pinhole with OpenCV axes (x right, y down, z forward) like the
// training cameras, started from one of them and moved by orbit / pan / zoom around a target.

const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const normalize = (a) => scale(a, 1 / (Math.hypot(...a) || 1));

// Rotates v about a unit axis by angle (Rodrigues).
function rotate(v, axis, angle) {
  const c = Math.cos(angle);
  const s = Math.sin(angle);
  return add(add(scale(v, c), scale(cross(axis, v), s)), scale(axis, dot(axis, v) * (1 - c)));
}

export class OrbitCamera {
  // A training camera from cameras.json; target: the point to orbit around.
  constructor(trainingCamera, target) {
    this.reset(trainingCamera, target);
  }

  reset(camera, target) {
    const m = camera.camera_to_world;
    this.right = [m[0][0], m[1][0], m[2][0]];
    this.down = [m[0][1], m[1][1], m[2][1]];
    this.forward = [m[0][2], m[1][2], m[2][2]];
    this.position = [m[0][3], m[1][3], m[2][3]];
    // Orbiting turns about the training camera's own up, so the horizon stays where it was.
    this.up = scale(this.down, -1);
    const depth = Math.max(1e-3, dot(sub(target, this.position), this.forward));
    this.target = add(this.position, scale(this.forward, depth));
    this.intrinsics = camera;
    this.atTrainingView = true;
  }

  distance() {
    return Math.hypot(...sub(this.position, this.target));
  }

  orbit(yaw, pitch) {
    const turn = (v) => rotate(rotate(v, this.up, yaw), normalize(rotate(this.right, this.up, yaw)), pitch);
    const offset = sub(this.position, this.target);
    const right = rotate(this.right, this.up, yaw);
    this.position = add(this.target, rotate(rotate(offset, this.up, yaw), normalize(right), pitch));
    this.forward = normalize(turn(this.forward));
    this.down = normalize(turn(this.down));
    this.right = normalize(cross(this.down, this.forward));
    this.atTrainingView = false;
  }

  pan(dx, dy) {
    const step = add(scale(this.right, -dx * this.distance()), scale(this.down, -dy * this.distance()));
    this.position = add(this.position, step);
    this.target = add(this.target, step);
    this.atTrainingView = false;
  }

  zoom(factor) {
    const offset = scale(sub(this.position, this.target), factor);
    if (Math.hypot(...offset) < 1e-4) return;
    this.position = add(this.target, offset);
    this.atTrainingView = false;
  }

  // World to camera, column-major for WebGL.
  viewMatrix() {
    const t = [-dot(this.right, this.position), -dot(this.down, this.position), -dot(this.forward, this.position)];
    const [r, d, f] = [this.right, this.down, this.forward];
    return new Float32Array([r[0], d[0], f[0], 0, r[1], d[1], f[1], 0, r[2], d[2], f[2], 0, t[0], t[1], t[2], 1]);
  }

  // The camera for a canvas of width x height: the training intrinsics scaled to it.
  forCanvas(width, height) {
    const camera = this.intrinsics;
    const sx = width / camera.width;
    const sy = height / camera.height;
    return { view: this.viewMatrix(), fx: camera.fx * sx, fy: camera.fy * sy, cx: camera.cx * sx, cy: camera.cy * sy };
  }

  // A world point's canvas pixel, or null behind the camera.
  project(point, canvasCamera) {
    const offset = sub(point, this.position);
    const z = dot(offset, this.forward);
    if (z <= 1e-4) return null;
    return [canvasCamera.fx * dot(offset, this.right) / z + canvasCamera.cx,
      canvasCamera.fy * dot(offset, this.down) / z + canvasCamera.cy];
  }
}

// The eight corners of an axis-aligned box.
export function boxCorners(min, max) {
  const corners = [];
  for (let i = 0; i < 8; i++) {
    corners.push([i & 1 ? max[0] : min[0], i & 2 ? max[1] : min[1], i & 4 ? max[2] : min[2]]);
  }
  return corners;
}

export const BOX_EDGES = [[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]];

// Mouse, touch and keyboard controls on an element; onChange after every move.
export function attachControls(element, getCamera, onChange) {
  let last = null;
  let mode = "orbit";
  element.addEventListener("pointerdown", (event) => {
    element.setPointerCapture(event.pointerId);
    last = [event.clientX, event.clientY];
    mode = event.button === 2 || event.shiftKey ? "pan" : "orbit";
  });
  element.addEventListener("pointermove", (event) => {
    const camera = getCamera();
    if (!last || !camera) return;
    const dx = event.clientX - last[0];
    const dy = event.clientY - last[1];
    last = [event.clientX, event.clientY];
    if (mode === "pan") camera.pan(dx / element.clientWidth, dy / element.clientHeight);
    else camera.orbit(-dx * 0.008, -dy * 0.008);
    onChange();
  });
  const end = () => {
    last = null;
  };
  element.addEventListener("pointerup", end);
  element.addEventListener("pointercancel", end);
  element.addEventListener("contextmenu", (event) => event.preventDefault());
  element.addEventListener("wheel", (event) => {
    const camera = getCamera();
    if (!camera) return;
    event.preventDefault();
    camera.zoom(Math.exp(event.deltaY * 0.001));
    onChange();
  }, { passive: false });
  element.addEventListener("keydown", (event) => {
    const camera = getCamera();
    if (!camera) return;
    const step = 0.08;
    const moves = {
      ArrowLeft: () => (event.shiftKey ? camera.pan(-step, 0) : camera.orbit(step, 0)),
      ArrowRight: () => (event.shiftKey ? camera.pan(step, 0) : camera.orbit(-step, 0)),
      ArrowUp: () => (event.shiftKey ? camera.pan(0, -step) : camera.orbit(0, step)),
      ArrowDown: () => (event.shiftKey ? camera.pan(0, step) : camera.orbit(0, -step)),
      "+": () => camera.zoom(0.9),
      "=": () => camera.zoom(0.9),
      "-": () => camera.zoom(1.1),
    };
    if (!moves[event.key]) return;
    event.preventDefault();
    moves[event.key]();
    onChange();
  });
}
