// The operators' page: readiness from /readyz, the job queue and workers from /metrics, the
// latest failed jobs, and a link to the Grafana dashboard when the server names one.

import { fetchWithToken, getJson, request } from "./api.js";
import { $, describeError, el, fillFacts, showError } from "./dom.js";

const RECENT_FAILURES = 10;

// Prometheus text format: {family: [[labels, value], ...]} for the families asked for.
export function parseMetrics(text, families) {
  const found = Object.fromEntries(families.map((family) => [family, []]));
  for (const line of text.split("\n")) {
    const match = line.match(/^([a-zA-Z_:][a-zA-Z0-9_:]*)(\{([^}]*)\})?\s+(\S+)/);
    if (!match || !(match[1] in found)) continue;
    const labels = Object.fromEntries([...(match[3] || "").matchAll(/(\w+)="((?:[^"\\]|\\.)*)"/g)]
      .map(([, name, value]) => [name, value]));
    found[match[1]].push([labels, Number(match[4])]);
  }
  return found;
}

// The warning the page shows when work waits and nothing can do it: jobs queued while no worker
// in the cluster is alive (busy or idle; silent ones are not). "Ready" is about this process
// (an API-only process is ready without workers), so it alone does not say this.
export function queueWarning(jobs, workers) {
  const count = (series, state) => series.find(([labels]) => labels.state === state)?.[1] ?? 0;
  const queued = count(jobs, "queued");
  const alive = count(workers, "busy") + count(workers, "idle");
  if (queued === 0 || alive > 0) return "";
  const silent = count(workers, "silent");
  return `${queued} job${queued === 1 ? "" : "s"} queued and no worker is alive` +
    (silent ? ` (${silent} silent: stopped answering)` : "") + ": nothing will run them until a worker starts.";
}

export class StatusPage {
  enter(_, settings) {
    document.title = "Status - segsplat";
    const link = $("grafana-link");
    link.hidden = !settings.grafana_url;
    if (settings.grafana_url) $("grafana-anchor").href = settings.grafana_url;
    this.refresh();
    clearInterval(this.timer);
    this.timer = setInterval(() => this.refresh(), 5000);
  }

  leave() {
    clearInterval(this.timer);
  }

  async refresh() {
    try {
      // /readyz answers 503 with the same body when not ready, which is worth showing too. With
      // the token it has the checks' details (without, only whether the service is ready).
      const readyResponse = await fetchWithToken("/readyz");
      const ready = await readyResponse.json();
      const checks = ready.checks || {};
      const detail = (name) => checks[name]?.detail ?? "(details need a token)";
      const metrics = await (await request("/metrics")).text();
      const { segsplat_jobs: jobs, segsplat_cluster_workers: workers } =
        parseMetrics(metrics, ["segsplat_jobs", "segsplat_cluster_workers"]);
      const workerCount = (state) => workers.find(([labels]) => labels.state === state)?.[1] ?? 0;
      fillFacts($("status-facts"), [
        ["Ready", ready.ready ? "yes" : `no: ${(ready.reasons || ["details need a token"]).join("; ")}`],
        ["Database", detail("database")],
        ["Blobs", detail("blobs")],
        ["GPU adapters", detail("adapters")],
        ["Models", detail("models")],
        ["Workers", `${workerCount("busy")} busy, ${workerCount("idle")} idle, ${workerCount("silent")} silent`],
      ]);
      const warning = queueWarning(jobs, workers);
      $("status-warning").textContent = warning;
      $("status-warning").hidden = !warning;
      $("queue-list").replaceChildren(...jobs.map(([labels, value]) =>
        el("tr", { "data-state": labels.state }, el("td", {}, labels.state), el("td", {}, String(value)))));
      const failed = (await getJson("/v1/jobs?state=failed")).jobs
        .sort((a, b) => (b.finished_at_ms ?? 0) - (a.finished_at_ms ?? 0))
        .slice(0, RECENT_FAILURES);
      $("failure-list").replaceChildren(...(failed.length ? failed.map((job) => el("li", {},
        `${new Date(job.finished_at_ms ?? job.updated_at_ms).toLocaleString()} ${job.kind} ${job.id}: `,
        el("span", { class: "error" }, job.error || "no reason given"))) : [el("li", {}, "None.")]));
      showError($("status-error"), "");
    } catch (error) {
      showError($("status-error"), describeError(error));
    }
  }
}
