// One scene: its facts, its jobs, the trained Gaussians in 3D with the objects of a level,
// text queries with their matches lit in 3D and their masks over a training view, and a time
// slider for dynamic scenes.

import { ApiFailure, download, getBytes, getJson, sendJson } from "./api.js";
import { $, activatable, cssColor, describeError, el, fillFacts, formatNumber, showError } from "./dom.js";
import { JobPanel } from "./jobs.js";
import { BOX_EDGES, OrbitCamera, attachControls, boxCorners } from "./orbit.js";
import { sceneFacts } from "./scenes.js";
import { LEVELS, NO_OBJECT, parseLabels, parseSplatPly } from "./splat_files.js";
import { SplatRenderer } from "./splat_renderer.js";

const MASK_COLORS = [[255, 196, 0], [0, 200, 255], [255, 64, 160], [120, 255, 80], [180, 120, 255]];

// The median of each coordinate: a robust point to orbit around (far floaters do not move it).
function medianCenter(centers, count) {
  const step = Math.max(1, Math.floor(count / 5000));
  return [0, 1, 2].map((axis) => {
    const values = [];
    for (let i = 0; i < count; i += step) values.push(centers[i * 3 + axis]);
    values.sort((a, b) => a - b);
    return values[Math.floor(values.length / 2)] ?? 0;
  });
}

function decodeBase64(data) {
  const binary = atob(data);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
  return bytes;
}

// A grey PNG mask (255 inside) as a canvas tinted with a colour, transparent outside.
async function tintedMask(mask, color) {
  const bitmap = await createImageBitmap(new Blob([decodeBase64(mask.data)], { type: "image/png" }));
  const canvas = document.createElement("canvas");
  canvas.width = bitmap.width;
  canvas.height = bitmap.height;
  const context = canvas.getContext("2d");
  context.drawImage(bitmap, 0, 0);
  const pixels = context.getImageData(0, 0, canvas.width, canvas.height);
  for (let i = 0; i < pixels.data.length; i += 4) {
    const inside = pixels.data[i] > 127;
    pixels.data.set(inside ? [...color, 140] : [0, 0, 0, 0], i);
  }
  context.putImageData(pixels, 0, 0);
  return canvas;
}

export class ScenePage {
  constructor() {
    this.jobs = new JobPanel(() => this.loadTrained());
    this.canvas = $("view3d");
    this.overlay = $("mask-overlay");
    this.renderer = null;
    this.camera = null;
    this.pinned = new Set();
    this.hovered = null;
    this.masks = [];
    this.frameCount = 0;
    // Queries asked so far: an answer that arrives after a newer query was asked is dropped, so
    // a slow answer never overwrites a newer one's masks and selection.
    this.queriesAsked = 0;
    attachControls(this.canvas, () => this.camera, () => {
      this.masks = [];
      this.requestDraw();
    });
    new ResizeObserver(() => this.requestDraw()).observe(this.canvas);
    $("camera-select").addEventListener("change", () => this.toTrainingView());
    $("level-select").addEventListener("change", () => this.showLevel($("level-select").value));
    $("overlay-clear").addEventListener("click", () => {
      this.masks = [];
      this.pinned.clear();
      this.applySelection();
    });
    $("query-form").addEventListener("submit", (event) => {
      event.preventDefault();
      this.ask();
    });
    $("time-slider").addEventListener("input", () => {
      $("time-value").textContent = Number($("time-slider").value).toFixed(2);
    });
    $("time-slider").addEventListener("change", () => this.moveToTime());
    // Test and automation hook: what the view shows, in canvas pixels.
    window.segsplatConsole = { view: this };
  }

  async enter(id) {
    this.sceneId = id;
    this.scene = null;
    this.objects = [];
    this.labels = null;
    this.masks = [];
    this.pinned.clear();
    this.lastQuery = null;
    this.cameras = null;
    this.camera = null;
    this.renderer?.clear();
    this.overlay.getContext("2d").clearRect(0, 0, this.overlay.width, this.overlay.height);
    $("query-results").replaceChildren();
    $("query-nothing").hidden = true;
    showError($("query-error"), "");
    $("object-list").replaceChildren();
    try {
      this.scene = await getJson(`/v1/scenes/${encodeURIComponent(id)}`);
    } catch (error) {
      $("scene-title").textContent = "Scene";
      fillFacts($("scene-facts"), [["Error", describeError(error)]]);
      return;
    }
    document.title = `${this.scene.name} - segsplat`;
    $("scene-title").textContent = this.scene.name;
    fillFacts($("scene-facts"), [["Id", this.scene.id], ...sceneFacts(this.scene)]);
    $("time-slider").hidden = !this.scene.dynamic;
    $("time-label").hidden = !this.scene.dynamic;
    $("time-slider").value = 0;
    $("time-value").textContent = "0.00";
    const jobs = await this.jobs.open(id);
    // Only a finished job leaves a trained version; asking for one before would only get a 409.
    if (jobs.some((job) => job.state === "succeeded")) this.loadTrained();
    else this.status("Not trained yet: start a job to see the scene here.");
  }

  leave() {
    this.jobs.stop();
  }

  path(suffix) {
    return `/v1/scenes/${encodeURIComponent(this.sceneId)}${suffix}`;
  }

  time() {
    return this.scene?.dynamic ? Number($("time-slider").value) : null;
  }

  status(message) {
    $("view-status").textContent = message;
  }

  // keepCamera: the same scene at another time, seen from where the user left the camera.
  async loadTrained(keepCamera = false) {
    const sceneId = this.sceneId;
    this.status("Loading the trained scene...");
    try {
      const [cameras, ply, labels] = await Promise.all([
        getJson(this.path("/trained/cameras.json")),
        getBytes(this.path(this.time() === null ? "/trained/scene.ply" : `/trained/scene.ply?time=${this.time()}`)),
        getBytes(this.path("/trained/labels.npy")).catch(() => null),
      ]);
      if (sceneId !== this.sceneId) return;
      this.cameras = cameras;
      this.splats = parseSplatPly(ply);
      this.labels = labels ? parseLabels(labels) : null;
      if (this.labels && this.labels.rows !== this.splats.count) this.labels = null;
      if (!this.renderer) this.renderer = new SplatRenderer(this.canvas);
      this.renderer.setSplats(this.splats, null);
      if (!keepCamera || !this.camera) {
        $("camera-select").replaceChildren(...cameras.map((camera, index) =>
          el("option", { value: String(index) }, `${index}: ${camera.name}`)));
        this.target = medianCenter(this.splats.centers, this.splats.count);
        this.toTrainingView();
      }
      await this.showLevel($("level-select").value);
      this.canvas.dataset.time = String(this.time() ?? "");
      this.status(`${formatNumber(this.splats.count, 0)} Gaussians. Drag to orbit, shift-drag to pan, wheel to zoom.`);
    } catch (error) {
      if (sceneId !== this.sceneId) return;
      const untrained = error instanceof ApiFailure && (error.status === 409 || error.status === 404);
      this.status(untrained ? "Not trained yet: start a job to see the scene here." : `Could not load the scene: ${describeError(error)}`);
    }
  }

  toTrainingView() {
    if (!this.cameras?.length) return;
    const index = Number($("camera-select").value || 0);
    const camera = this.cameras[index];
    // The stage keeps the training camera's aspect, so its pixels are square in the view.
    $("view-stage").style.setProperty("--aspect", String(camera.width / camera.height));
    if (this.camera) this.camera.reset(camera, this.target);
    else this.camera = new OrbitCamera(camera, this.target);
    this.masks = [];
    this.requestDraw();
  }

  objectIdsFor(level) {
    if (!this.labels) return null;
    const column = LEVELS.indexOf(level);
    const ids = new Float32Array(this.labels.rows);
    for (let i = 0; i < ids.length; i++) {
      const id = this.labels.ids[i * 3 + column];
      ids[i] = id === NO_OBJECT ? -1 : id;
    }
    return ids;
  }

  async showLevel(level) {
    $("level-select").value = level;
    this.level = level;
    this.pinned.clear();
    this.hovered = null;
    if (this.renderer && this.splats) this.renderer.setObjectIds(this.objectIdsFor(level));
    try {
      const time = this.time();
      const query = `?level=${level}${time === null ? "" : `&time=${time}`}`;
      const { objects } = await getJson(this.path(`/objects${query}`));
      this.objects = objects;
    } catch (error) {
      this.objects = [];
      if (!(error instanceof ApiFailure && error.status === 409)) this.status(describeError(error));
    }
    this.listObjects();
    this.applySelection();
  }

  listObjects() {
    $("objects-empty").hidden = this.objects.length > 0;
    $("object-list").replaceChildren(...this.objects.map((object) => {
      const fileName = `${this.scene.name}-${object.level}-${object.object_id}.ply`;
      const save = el("button", {
        type: "button",
        class: "download",
        "aria-label": `Download object ${object.object_id} as PLY`,
        onclick: (event) => {
          event.stopPropagation();
          download(this.path(`/objects/${object.level}/${object.object_id}/ply`), fileName)
            .catch((error) => this.status(`Download failed: ${describeError(error)}`));
        },
      }, "PLY");
      const row = activatable(el("tr", {
        "data-object-id": String(object.object_id),
        "aria-label": `Object ${object.object_id}: select to highlight`,
      },
      el("td", {}, el("span", { class: "swatch", "data-color": cssColor(object.mean_color) }), `#${object.object_id}`),
      el("td", {}, formatNumber(object.gaussian_count, 0)),
      el("td", {}, `${object.bounds_min.map((v) => v.toFixed(2)).join(", ")} / ${object.bounds_max.map((v) => v.toFixed(2)).join(", ")}`),
      el("td", {}, save)), () => this.toggle(object.object_id));
      row.querySelector(".swatch").style.background = cssColor(object.mean_color);
      row.addEventListener("pointerenter", () => this.hover(object.object_id));
      row.addEventListener("pointerleave", () => this.hover(null));
      row.addEventListener("focus", () => this.hover(object.object_id));
      row.addEventListener("blur", () => this.hover(null));
      return row;
    }));
  }

  hover(id) {
    this.hovered = id;
    this.applySelection();
  }

  toggle(id) {
    if (this.pinned.has(id)) this.pinned.delete(id);
    else this.pinned.add(id);
    this.applySelection();
  }

  highlighted() {
    const ids = new Set(this.pinned);
    if (this.hovered !== null) ids.add(this.hovered);
    return [...ids];
  }

  applySelection() {
    const ids = this.highlighted();
    for (const row of $("object-list").children) {
      const selected = ids.includes(Number(row.dataset.objectId));
      row.classList.toggle("selected", selected);
      row.setAttribute("aria-selected", String(selected));
    }
    this.renderer?.select(ids);
    this.requestDraw();
  }

  // The canvas-pixel rectangle (CSS pixels) an object's bounds project to, for tests and tools.
  projectedBox(objectId) {
    const object = this.objects.find((candidate) => candidate.object_id === objectId);
    if (!object || !this.camera) return null;
    const camera = this.camera.forCanvas(this.canvas.clientWidth, this.canvas.clientHeight);
    const points = boxCorners(object.bounds_min, object.bounds_max).map((corner) => this.camera.project(corner, camera));
    if (points.some((point) => point === null)) return null;
    const xs = points.map(([x]) => x);
    const ys = points.map(([, y]) => y);
    return { x0: Math.min(...xs), y0: Math.min(...ys), x1: Math.max(...xs), y1: Math.max(...ys) };
  }

  requestDraw() {
    if (this.drawPending) return;
    this.drawPending = true;
    requestAnimationFrame(() => {
      this.drawPending = false;
      this.draw();
    });
  }

  draw() {
    if (!this.renderer || !this.camera) return;
    const ratio = window.devicePixelRatio || 1;
    const width = Math.max(1, Math.round(this.canvas.clientWidth * ratio));
    const height = Math.max(1, Math.round(this.canvas.clientHeight * ratio));
    for (const canvas of [this.canvas, this.overlay]) {
      if (canvas.width !== width || canvas.height !== height) {
        canvas.width = width;
        canvas.height = height;
      }
    }
    const camera = this.camera.forCanvas(width, height);
    this.renderer.draw(camera);
    this.drawOverlay(camera);
    this.canvas.dataset.frames = String(Number(this.canvas.dataset.frames || 0) + 1);
    this.canvas.dataset.selected = this.highlighted().join(",");
    this.canvas.dataset.masks = String(this.masks.length);
  }

  drawOverlay(camera) {
    const context = this.overlay.getContext("2d");
    context.clearRect(0, 0, this.overlay.width, this.overlay.height);
    for (const mask of this.masks) context.drawImage(mask, 0, 0, this.overlay.width, this.overlay.height);
    context.lineWidth = 2 * (window.devicePixelRatio || 1);
    context.strokeStyle = "rgb(255, 220, 40)";
    for (const id of this.highlighted()) {
      const object = this.objects.find((candidate) => candidate.object_id === id);
      if (!object) continue;
      const corners = boxCorners(object.bounds_min, object.bounds_max).map((corner) => this.camera.project(corner, camera));
      context.beginPath();
      for (const [a, b] of BOX_EDGES) {
        if (!corners[a] || !corners[b]) continue;
        context.moveTo(...corners[a]);
        context.lineTo(...corners[b]);
      }
      context.stroke();
    }
  }

  queryRequest() {
    const request = {
      text: $("query-text").value,
      granularity: $("query-granularity").value,
      top_k: Number($("query-topk").value || 3),
      mask_format: "png",
      visible_masks: $("query-visible").checked,
    };
    if ($("query-threshold").value !== "") request.threshold = Number($("query-threshold").value);
    if (this.cameras?.length) {
      request.view = { frame_index: Number($("camera-select").value || 0) };
      if (this.time() !== null) request.view.time = this.time();
    }
    if (this.time() !== null) request.time = this.time();
    return request;
  }

  async ask() {
    const asked = ++this.queriesAsked;
    const superseded = () => asked !== this.queriesAsked;
    showError($("query-error"), "");
    $("query-nothing").hidden = true;
    $("query-results").replaceChildren();
    let answer;
    try {
      answer = await sendJson("POST", this.path("/query"), this.queryRequest());
    } catch (error) {
      if (!superseded()) showError($("query-error"), describeError(error));
      return;
    }
    if (superseded()) return;
    this.lastQuery = answer;
    if (!answer.matched || !answer.objects.length) {
      $("query-nothing").hidden = false;
      this.masks = [];
      this.pinned.clear();
      this.applySelection();
      this.answered(asked);
      return;
    }
    $("query-results").replaceChildren(...answer.objects.map((match, index) => el("li", {
      "data-object-id": String(match.object_id),
    }, el("span", { class: "swatch", "data-mask-color": String(index % MASK_COLORS.length) }),
    `${match.level} #${match.object_id}: score ${match.score.toFixed(3)}, relevancy ${match.relevancy.toFixed(2)}`)));
    for (const swatch of $("query-results").querySelectorAll(".swatch")) {
      swatch.style.background = `rgb(${MASK_COLORS[Number(swatch.dataset.maskColor)].join(",")})`;
    }
    const level = answer.objects[0].level;
    if (level !== this.level) await this.showLevel(level);
    if (superseded()) return;
    this.toTrainingView();
    const masks = answer.objects.map((match, index) => {
      const mask = $("query-visible").checked ? match.visible_mask || match.mask : match.mask;
      return mask ? tintedMask(mask, MASK_COLORS[index % MASK_COLORS.length]) : null;
    });
    const tinted = (await Promise.all(masks)).filter(Boolean);
    if (superseded()) return;
    this.masks = tinted;
    this.pinned = new Set(answer.objects.filter((match) => match.level === level).map((match) => match.object_id));
    this.applySelection();
    this.answered(asked);
  }

  // Test and automation hook: the number of the last query whose answer the view shows.
  answered(asked) {
    $("query-results").dataset.answered = String(asked);
  }

  async moveToTime() {
    if (!this.scene?.dynamic) return;
    await this.loadTrained(true);
    if (this.lastQuery?.matched) await this.ask();
  }
}
