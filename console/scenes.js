// The scenes page: the list, uploads (drop or pick, with progress) and deletes.

import { getJson, request, upload } from "./api.js";
import { $, activatable, describeError, el, fillFacts, showError } from "./dom.js";

// A scene's image sizes for the table: one size as is; several as a count and the range
// (smallest to largest by pixels), the full list in the cell's tooltip, so a capture with many
// frame sizes does not widen the table past the window.
export function sizesSummary(resolutions) {
  const sizes = resolutions.map(([w, h]) => `${w}x${h}`);
  if (sizes.length <= 2) return { text: sizes.join(", ") || "-", title: "" };
  const byPixels = [...resolutions].sort((a, b) => a[0] * a[1] - b[0] * b[1]);
  const [small, large] = [byPixels[0], byPixels[byPixels.length - 1]];
  return {
    text: `${sizes.length} sizes, ${small[0]}x${small[1]} to ${large[0]}x${large[1]}`,
    title: sizes.join(", "),
  };
}

export function sceneFacts(scene) {
  return [
    ["Format", scene.format],
    ["Frames", String(scene.frame_count)],
    ["Resolution", scene.resolutions.map(([w, h]) => `${w}x${h}`).join(", ") || "-"],
    ["Dynamic", scene.dynamic ? `yes (${scene.time_count} times)` : "no"],
    ["Sparse points", String(scene.sparse_point_count)],
    ["Mask levels", scene.mask_levels.join(", ") || "none"],
  ];
}

export class ScenesPage {
  constructor() {
    const zone = $("drop-zone");
    zone.addEventListener("dragover", (event) => {
      event.preventDefault();
      zone.classList.add("over");
    });
    zone.addEventListener("dragleave", () => zone.classList.remove("over"));
    zone.addEventListener("drop", (event) => {
      event.preventDefault();
      zone.classList.remove("over");
      const [file] = event.dataTransfer.files;
      if (file) this.upload(file);
    });
    zone.addEventListener("keydown", (event) => {
      if (event.target === zone && (event.key === "Enter" || event.key === " ")) {
        event.preventDefault();
        $("upload-input").click();
      }
    });
    $("upload-input").addEventListener("change", () => {
      const [file] = $("upload-input").files;
      if (file) this.upload(file);
      $("upload-input").value = "";
    });
  }

  enter() {
    document.title = "Scenes - segsplat";
    this.refresh();
  }

  async refresh() {
    try {
      const { scenes } = await getJson("/v1/scenes");
      showError($("scenes-error"), "");
      $("scenes-empty").hidden = scenes.length > 0;
      $("scene-list").replaceChildren(...scenes.map((scene) => this.row(scene)));
    } catch (error) {
      showError($("scenes-error"), describeError(error));
    }
  }

  row(scene) {
    const open = () => {
      location.hash = `#/scenes/${encodeURIComponent(scene.id)}`;
    };
    const remove = el("button", {
      type: "button",
      class: "delete",
      "aria-label": `Delete ${scene.name}`,
      onclick: (event) => {
        event.stopPropagation();
        this.remove(scene);
      },
    }, "Delete");
    return activatable(
      el("tr", { "data-scene-id": scene.id, "aria-label": `Open ${scene.name}` },
        el("td", {}, scene.name),
        el("td", {}, scene.format),
        el("td", {}, String(scene.frame_count)),
        sizesCell(scene.resolutions),
        el("td", {}, scene.dynamic ? "yes" : "no"),
        el("td", {}, new Date(scene.created_at_ms).toLocaleString()),
        el("td", {}, remove)),
      open,
    );
  }

  async remove(scene) {
    if (!window.confirm(`Delete scene ${scene.name}? Its trained results go with it.`)) return;
    let failure = "";
    try {
      await request(`/v1/scenes/${encodeURIComponent(scene.id)}`, { method: "DELETE" });
    } catch (error) {
      failure = `Could not delete ${scene.name}: ${describeError(error)}`;
    }
    await this.refresh();
    showError($("scenes-error"), failure);
  }

  async upload(file) {
    const progress = $("upload-progress");
    progress.hidden = false;
    progress.value = 0;
    showError($("upload-error"), "");
    $("upload-result").hidden = true;
    $("upload-status").textContent = `Uploading ${file.name}...`;
    try {
      // The scene is named after the file, without its archive extension.
      const name = file.name.replace(/\.(zip|tar|tgz|tar\.gz|gz)$/i, "");
      const scene = await upload(`/v1/scenes?name=${encodeURIComponent(name)}`, file, (fraction) => {
        progress.value = fraction;
        $("upload-status").textContent =
          fraction < 1 ? `Uploading ${file.name}: ${Math.round(fraction * 100)}%`
            : `Checking ${file.name} on the server...`;
      });
      $("upload-status").textContent = `Uploaded ${scene.name}.`;
      fillFacts($("upload-result"), [["Scene", scene.name], ...sceneFacts(scene)]);
      $("upload-result").hidden = false;
    } catch (error) {
      $("upload-status").textContent = "";
      showError($("upload-error"), `Upload refused: ${describeError(error)}`);
    } finally {
      progress.hidden = true;
    }
    this.refresh();
  }
}

function sizesCell(resolutions) {
  const { text, title } = sizesSummary(resolutions);
  return el("td", title ? { class: "sizes", title } : { class: "sizes" }, text);
}
