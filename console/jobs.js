// A scene's jobs: start one with the common options, follow it live from its event stream
// (stage, step, loss, PSNR, Gaussians, ETA, a loss chart), cancel it, and list the earlier ones.

import { followEvents, getJson, sendJson } from "./api.js";
import { LineChart } from "./chart.js";
import { $, describeError, el, fillFacts, formatNumber, formatSeconds, showError } from "./dom.js";

const FINAL_STATES = ["succeeded", "failed", "cancelled"];

export class JobPanel {
  // onFinished(job) is called when a followed job reaches a final state.
  constructor(onFinished) {
    this.onFinished = onFinished;
    this.chart = new LineChart($("loss-chart"), "loss");
    this.following = null;
    this.sceneId = null;
    $("job-form").addEventListener("submit", (event) => {
      event.preventDefault();
      this.start();
    });
    $("job-kind").addEventListener("change", () => this.showMaskChoice());
    $("job-cancel").addEventListener("click", () => this.cancel());
  }

  showMaskChoice() {
    const masks = $("job-kind").value === "segment_then_splat";
    $("job-masks").disabled = !masks;
  }

  // Shows the scene's latest job (following it when it runs); resolves to the scene's jobs.
  async open(sceneId) {
    this.stop();
    this.sceneId = sceneId;
    $("job-live").hidden = true;
    showError($("job-form-error"), "");
    this.showMaskChoice();
    const jobs = await this.history();
    const active = jobs.find((job) => !FINAL_STATES.includes(job.state));
    if (active) this.follow(active);
    else if (jobs[0]) this.show(jobs[0]);
    return jobs;
  }

  stop() {
    this.following?.abort();
    this.following = null;
  }

  async history() {
    try {
      const { jobs } = await getJson("/v1/jobs");
      const mine = jobs
        .filter((job) => job.scene_id === this.sceneId)
        .sort((a, b) => b.created_at_ms - a.created_at_ms);
      $("job-history").replaceChildren(...mine.map((job) => el("li", {},
        el("span", { class: `badge ${job.state}` }, job.state), " ",
        `${job.kind}, ${job.config.steps ?? "?"} steps, ${new Date(job.created_at_ms).toLocaleString()}`,
        job.error ? el("span", { class: "error" }, ` - ${job.error}`) : null)));
      return mine;
    } catch (error) {
      showError($("job-form-error"), describeError(error));
      return [];
    }
  }

  config() {
    const config = { steps: Number($("job-steps").value) };
    const resolution = $("job-resolution").value;
    if (resolution) config.max_resolution = Number(resolution);
    if ($("job-kind").value === "segment_then_splat") config.masks = $("job-masks").value;
    config.checkpoint_every = Math.max(1, Math.min(1000, Math.floor(config.steps / 2)));
    return config;
  }

  async start() {
    showError($("job-form-error"), "");
    try {
      const job = await sendJson("POST", `/v1/scenes/${encodeURIComponent(this.sceneId)}/jobs`, {
        kind: $("job-kind").value,
        config: this.config(),
      });
      this.history();
      this.follow(job);
    } catch (error) {
      showError($("job-form-error"), `Could not start the job: ${describeError(error)}`);
    }
  }

  async cancel() {
    if (!this.job) return;
    try {
      const job = await sendJson("POST", `/v1/jobs/${encodeURIComponent(this.job.id)}/cancel`);
      this.showState(job.state, job.error);
    } catch (error) {
      showError($("job-error"), `Could not cancel: ${describeError(error)}`);
    }
  }

  // The job's last known state without following it.
  show(job) {
    this.job = job;
    $("job-live").hidden = false;
    $("job-title").textContent = `${job.kind} ${job.id}`;
    this.chart.clear();
    $("loss-chart").hidden = false;
    $("job-final").hidden = true;
    $("job-facts").hidden = false;
    for (const id of ["job-stage", "job-step", "job-loss", "job-psnr", "job-gaussians", "job-eta"]) {
      $(id).textContent = "-";
    }
    showError($("job-error"), "");
    this.showProgress(job.progress || {});
    this.showState(job.state, job.error);
    if (job.state === "succeeded") this.showFinal(job);
  }

  // A finished job's figures instead of its last progress report: held-out PSNR / SSIM,
  // Gaussians and objects per level from its metrics.json, wall time by stage from its events.
  async showFinal(job) {
    const path = `/v1/jobs/${encodeURIComponent(job.id)}/events`;
    const [metrics, stages] = await Promise.all([
      getJson(`/v1/scenes/${encodeURIComponent(job.scene_id)}/trained/metrics.json`).catch(() => null),
      stageTimes(path).catch(() => []),
    ]);
    if (this.job?.id !== job.id) return;
    const facts = [];
    const heldOut = metrics?.held_out;
    const evaluated = stages.evaluate || {};
    const psnr = heldOut?.psnr ?? evaluated.psnr;
    const ssim = heldOut?.ssim ?? evaluated.ssim;
    const gaussians = metrics?.gaussians ?? evaluated.gaussians;
    facts.push(["Held-out PSNR", Number.isFinite(psnr) ? `${formatNumber(psnr, 2)} dB` : "no held-out views"]);
    if (Number.isFinite(ssim)) facts.push(["Held-out SSIM", formatNumber(ssim, 3)]);
    if (Number.isFinite(gaussians)) facts.push(["Gaussians", formatNumber(gaussians, 0)]);
    if (Array.isArray(metrics?.objects)) {
      const [small, middle, large] = metrics.objects;
      facts.push(["Objects", `${small} small, ${middle} middle, ${large} large`]);
    }
    if (Number.isFinite(metrics?.steps)) facts.push(["Steps", String(metrics.steps)]);
    const walls = stages.order || [];
    if (walls.length) {
      facts.push(["Wall time", walls.map(([stage, seconds]) => `${stage} ${formatSeconds(seconds)}`).join(", ")]);
    }
    if (job.started_at_ms && job.finished_at_ms) {
      facts.push(["Total", formatSeconds((job.finished_at_ms - job.started_at_ms) / 1000)]);
    }
    fillFacts($("job-final-facts"), facts);
    $("job-final").hidden = false;
    $("job-facts").hidden = true;
    if (this.chart.points.length < 2) $("loss-chart").hidden = true;
  }

  follow(job) {
    this.stop();
    this.show(job);
    const controller = new AbortController();
    this.following = controller;
    const path = `/v1/jobs/${encodeURIComponent(job.id)}/events`;
    let finalState = null;
    followEvents(path, (kind, event) => {
      if (kind === "progress") this.showProgress(event.payload);
      else if (kind === "state") {
        this.showState(event.payload.state, event.payload.error);
        if (FINAL_STATES.includes(event.payload.state)) finalState = event.payload.state;
      } else if (kind === "warning") {
        showError($("job-error"), `Warning: ${event.payload.message || JSON.stringify(event.payload)}`);
      }
    }, controller.signal)
      .catch((error) => {
        if (error.name !== "AbortError") showError($("job-error"), describeError(error));
      })
      .finally(async () => {
        if (this.following !== controller) return;
        this.following = null;
        const latest = await getJson(path.replace(/\/events$/, "")).catch(() => null);
        if (latest) this.showState(latest.state, latest.error);
        if (latest?.state === "succeeded") this.showFinal(latest);
        this.history();
        if ((latest?.state || finalState) === "succeeded") this.onFinished(latest || job);
      });
  }

  showProgress(progress) {
    const metrics = progress.metrics || {};
    const step = progress.step ?? 0;
    const total = progress.total_steps ?? 0;
    $("job-stage").textContent = progress.stage || "-";
    $("job-step").textContent = total ? `${step} / ${total}` : "-";
    $("job-progress").value = total ? step / total : 0;
    if (metrics.loss !== undefined) {
      $("job-loss").textContent = formatNumber(metrics.loss, 4);
      if (progress.stage === "train") this.chart.add(step, metrics.loss);
    }
    if (metrics.psnr !== undefined) $("job-psnr").textContent = `${formatNumber(metrics.psnr, 2)} dB`;
    if (metrics.gaussians !== undefined) $("job-gaussians").textContent = formatNumber(metrics.gaussians, 0);
    $("job-eta").textContent = formatSeconds(progress.eta_secs);
  }

  showState(state, error) {
    const badge = $("job-state");
    badge.textContent = state;
    badge.className = `badge ${state}`;
    $("job-live").dataset.state = state;
    $("job-cancel").hidden = FINAL_STATES.includes(state);
    if (state === "failed") showError($("job-error"), `The job failed: ${error || "no reason given"}`);
    else if (state === "cancelled") showError($("job-error"), "The job was cancelled.");
    else if (state === "succeeded") {
      showError($("job-error"), "");
      $("job-progress").value = 1;
    }
  }
}

// Wall time per stage from a finished job's events: each stage runs from its first progress
// event (the job's start for the first) to the next stage's first, the last to the final state.
// Also the last metrics of each stage (the "evaluate" stage's PSNR / SSIM).
async function stageTimes(path) {
  const events = [];
  await followEvents(path, (kind, event) => events.push({ kind, ...event }));
  const result = { order: [] };
  let startMs = null;
  let current = null;
  const close = (atMs) => {
    if (current) result.order.push([current.stage, Math.max(0, (atMs - current.from) / 1000)]);
  };
  for (const event of events) {
    if (event.kind === "state" && event.payload?.state === "running" && startMs === null) startMs = event.at_ms;
    if (event.kind === "progress") {
      const stage = event.payload?.stage;
      if (stage && stage !== current?.stage) {
        close(event.at_ms);
        current = { stage, from: current ? event.at_ms : (startMs ?? event.at_ms) };
      }
      if (stage) result[stage] = event.payload.metrics || {};
    }
    if (event.kind === "state" && event.payload?.state === "succeeded") {
      close(event.at_ms);
      current = null;
    }
  }
  return result;
}
