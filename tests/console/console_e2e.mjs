// The web console in a real browser, against a real `segsplat serve` (scripts/console_e2e.sh
// starts the server and sets the environment). Each step checks what a person would see; the
// screenshots go to SEGSPLAT_CONSOLE_SHOTS.

import assert from "node:assert/strict";
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";
import path from "node:path";

const env = (name) => {
  const value = process.env[name];
  if (!value) throw new Error(`${name} is not set (run scripts/console_e2e.sh)`);
  return value;
};
const require = createRequire(import.meta.url);
const { chromium } = require(env("SEGSPLAT_PLAYWRIGHT"));
const base = env("SEGSPLAT_URL");
const token = env("SEGSPLAT_TOKEN");
const shots = env("SEGSPLAT_CONSOLE_SHOTS");
const JOB_STEPS = 80;
const DYNAMIC_STEPS = 300;
// The synthetic scene's green sphere at the small level (the tiny CLIP model knows colours).
const GREEN_OBJECT = 2;

// Console errors are failures, except the failed loads a step provokes on purpose (a refused
// token, a refused upload, a refused delete), which Chromium also logs as errors.
let phase = "start";
const expectedRefusals = { "wrong token": [401], "bad upload": [400, 413, 415, 422], "delete running": [409] };
const consoleErrors = [];

function step(name) {
  phase = name;
  console.log(`== ${name}`);
}

async function api(method, route, body) {
  const response = await fetch(`${base}${route}`, {
    method,
    headers: { Authorization: `Bearer ${token}`, "Content-Type": "application/json" },
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  return { status: response.status, body: await response.json().catch(() => null) };
}

// Uploads an archive straight to the API (not through the page), as a client would.
async function uploadArchive(file, name) {
  const query = name === undefined ? "" : `?name=${encodeURIComponent(name)}`;
  const response = await fetch(`${base}/v1/scenes${query}`, {
    method: "POST",
    headers: { Authorization: `Bearer ${token}`, "Content-Type": "application/zip" },
    body: readFileSync(file),
  });
  return { status: response.status, body: await response.json().catch(() => null) };
}

async function shot(page, name) {
  await page.screenshot({ path: path.join(shots, `${name}.png`), fullPage: false });
}

// The WebGL canvas's pixels (it keeps its drawing buffer), as RGBA bytes with its size. They
// cross from the page as one base64 string: returned as an array, Playwright serialises every
// byte as its own JSON object: with those few million objects per call the whole console check
// took 137 s and as many CPU-seconds, against 41 s and 36 CPU-seconds this way.
async function canvasPixels(page, selector) {
  const image = await page.evaluate((selector) => {
    const source = document.querySelector(selector);
    const copy = document.createElement("canvas");
    copy.width = source.width;
    copy.height = source.height;
    const context = copy.getContext("2d");
    context.drawImage(source, 0, 0);
    const { data } = context.getImageData(0, 0, copy.width, copy.height);
    let binary = "";
    for (let start = 0; start < data.length; start += 0x8000) {
      binary += String.fromCharCode.apply(null, data.subarray(start, start + 0x8000));
    }
    return { width: copy.width, height: copy.height, cssWidth: source.clientWidth, base64: btoa(binary) };
  }, selector);
  const { base64, ...size } = image;
  return { ...size, data: Buffer.from(base64, "base64") };
}

// Mean over a rectangle (canvas pixels) of f(pixel index), and over everything outside it.
function insideOutside(image, box, f) {
  let inside = 0;
  let insideCount = 0;
  let outside = 0;
  let outsideCount = 0;
  for (let y = 0; y < image.height; y++) {
    for (let x = 0; x < image.width; x++) {
      const value = f((y * image.width + x) * 4);
      if (x >= box.x0 && x <= box.x1 && y >= box.y0 && y <= box.y1) {
        inside += value;
        insideCount++;
      } else {
        outside += value;
        outsideCount++;
      }
    }
  }
  return { inside: inside / Math.max(1, insideCount), outside: outside / Math.max(1, outsideCount) };
}

async function waitForFrames(page, atLeast) {
  await page.waitForFunction((atLeast) => Number(document.getElementById("view3d").dataset.frames || 0) >= atLeast, atLeast);
}

async function main() {
  const browser = await chromium.launch({
    executablePath: env("SEGSPLAT_CHROMIUM"),
    headless: true,
    // No GPU in CI: WebGL2 through SwiftShader, which Chromium only uses when asked.
    args: ["--enable-unsafe-swiftshader", "--use-angle=swiftshader", "--ignore-gpu-blocklist", "--no-sandbox"],
  });
  const context = await browser.newContext({ viewport: { width: 1280, height: 800 }, acceptDownloads: true });
  const page = await context.newPage();
  page.setDefaultTimeout(30_000);
  page.on("console", (message) => {
    if (message.type() !== "error") return;
    const status = Number((message.text().match(/status of (\d{3})/) || [])[1]);
    if ((expectedRefusals[phase] || []).includes(status)) return;
    const where = message.location();
    consoleErrors.push(`[${phase}] ${message.text()} (${where.url}:${where.lineNumber})`);
  });
  page.on("response", (response) => {
    if (response.status() >= 400) console.log(`   ${response.status()} ${response.request().method()} ${response.url()}`);
  });
  page.on("pageerror", (error) => consoleErrors.push(`[${phase}] page error: ${error.message}`));
  page.on("dialog", (dialog) => dialog.accept());

  try {
    step("wrong token");
    await page.goto(base);
    await page.locator("#token-panel").waitFor();
    await page.fill("#token-input", "not-the-token");
    await page.click("#token-save");
    await page.locator("#token-error").filter({ hasText: "refused" }).waitFor();
    assert.ok(await page.locator("#scenes-page").isHidden(), "nothing shows without an accepted token");
    await shot(page, "01-token-refused");

    step("token");
    await page.fill("#token-input", token);
    await page.click("#token-save");
    await page.locator("#scenes-page").waitFor();

    step("bad upload");
    // Dropped on the drop zone, as a person would; the server's own 4xx message is shown.
    await page.evaluate(() => {
      const transfer = new DataTransfer();
      transfer.items.add(new File(["this is not an archive"], "not-a-scene.zip", { type: "application/zip" }));
      document.getElementById("drop-zone").dispatchEvent(new DragEvent("drop", { dataTransfer: transfer, bubbles: true, cancelable: true }));
    });
    const refusal = page.locator("#upload-error");
    await refusal.filter({ hasText: /Upload refused: 4\d\d / }).waitFor();
    const direct = await uploadArchive(env("SEGSPLAT_BAD_UPLOAD"));
    const directMessage = direct.body.error.message;
    assert.ok((await refusal.textContent()).includes(directMessage), `the server's message is shown as it is: ${directMessage}`);
    await shot(page, "02-bad-upload");

    step("upload");
    await page.setInputFiles("#upload-input", env("SEGSPLAT_SCENE_ZIP"));
    const result = page.locator("#upload-result");
    await result.waitFor();
    const facts = await result.textContent();
    for (const expected of ["colmap", "9", "96x72", "no"]) assert.ok(facts.includes(expected), `upload facts show ${expected}: ${facts}`);
    const row = page.locator("#scene-list tr").first();
    await row.waitFor();
    assert.ok((await row.textContent()).startsWith("scene"), "the scene is named after its file");

    step("many sizes");
    // A capture with several frame sizes (the figurine has 7) keeps the table inside 1280x800:
    // the cell gives the count and the range, the tooltip every size; "Uploaded" and "Delete"
    // stay on screen.
    const figurineSizes = [[3024, 4032], [4032, 3024], [2268, 4032], [4032, 2268], [3000, 4000],
      [4000, 3000], [1080, 1920]];
    const manySizes = async (route) => {
      const response = await route.fetch();
      const body = await response.json();
      for (const scene of body.scenes) scene.resolutions = figurineSizes;
      await route.fulfill({ response, json: body });
    };
    await page.route(/\/v1\/scenes$/, manySizes);
    await page.reload();
    await page.locator("#scene-list tr td.sizes").filter({ hasText: "7 sizes" }).first().waitFor();
    const sizesCell = page.locator("#scene-list tr td.sizes").first();
    assert.equal(await sizesCell.textContent(), "7 sizes, 1080x1920 to 4032x3024");
    assert.ok((await sizesCell.getAttribute("title")).includes("4032x2268"), "every size in the tooltip");
    const tableWidth = await page.evaluate(() => document.getElementById("scene-table").getBoundingClientRect().width);
    const deleteRight = await page.locator("#scene-list tr button.delete").first().evaluate((button) => button.getBoundingClientRect().right);
    const pageOverflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    assert.ok(tableWidth <= 1280 && deleteRight <= 1280 && pageOverflow <= 1,
      `the scenes table fits 1280 px (table ${tableWidth} px, Delete's right edge ${deleteRight} px, overflow ${pageOverflow} px)`);
    await shot(page, "02b-many-sizes");
    await page.unroute(/\/v1\/scenes$/, manySizes);
    await page.reload();
    await page.locator("#scene-list tr").first().waitFor();

    step("job");
    await row.click();
    await page.locator("#scene-page").waitFor();
    await page.locator("#view-status").filter({ hasText: "Not trained yet" }).waitFor();
    await page.selectOption("#job-kind", "segment_then_splat");
    await page.fill("#job-steps", String(JOB_STEPS));
    await page.selectOption("#job-masks", "user");
    await page.click("#job-start");
    await page.locator("#job-live").waitFor();
    const seenSteps = new Set();
    await page.waitForFunction(() => /^\d+ \/ \d+$/.test(document.getElementById("job-step").textContent)
      && Number(document.getElementById("job-step").textContent.split(" / ")[0]) > 0, null, { timeout: 240_000 });
    seenSteps.add(await page.textContent("#job-step"));
    await shot(page, "03-job-running");
    await page.waitForFunction(() => document.getElementById("job-live").dataset.state === "succeeded", null, { timeout: 300_000 });
    seenSteps.add(await page.textContent("#job-step"));
    assert.ok(seenSteps.size >= 1);
    assert.equal(await page.locator("#job-progress").evaluate((bar) => bar.value), 1, "the bar is full");
    assert.ok(!(await page.textContent("#job-loss")).startsWith("-"), "a loss was shown");
    // Done, the panel shows the job's final figures instead of its last progress report
    // ("persist 1/1", "-" for the loss) and no empty loss chart.
    await page.locator("#job-final").waitFor();
    const final = await page.textContent("#job-final-facts");
    assert.match(final, /Held-out PSNR(\d[\d.,]* dB|no held-out views)/, final);
    assert.match(final, /Gaussians\d/, final);
    assert.match(final, /Objects\d+ small, \d+ middle, \d+ large/, final);
    assert.match(final, /Wall time.*segment \d+ s.*train \d+ s/, final);
    assert.ok(await page.locator("#job-facts").isHidden(), "the live figures give way to the final ones");
    await shot(page, "03b-job-done");

    step("3d view");
    await page.locator("#view-status").filter({ hasText: "Gaussians" }).waitFor({ timeout: 60_000 });
    await page.locator("#object-list tr").first().waitFor();
    await waitForFrames(page, 1);
    await page.waitForTimeout(300);
    const before = await canvasPixels(page, "#view3d");
    const lit = before.data.filter((_, i) => i % 4 === 0).filter((_, p) => {
      const i = p * 4;
      return before.data[i] + before.data[i + 1] + before.data[i + 2] > 30;
    }).length;
    assert.ok(lit > before.width * before.height * 0.01, `the view shows the scene (${lit} lit pixels)`);
    await page.locator("#view-panel").scrollIntoViewIfNeeded();
    await shot(page, "04-scene-3d");

    step("orbit by keyboard");
    const framesBefore = Number(await page.locator("#view3d").getAttribute("data-frames"));
    await page.focus("#view3d");
    await page.keyboard.press("ArrowLeft");
    await waitForFrames(page, framesBefore + 1);
    await page.selectOption("#camera-select", "0");
    await page.dispatchEvent("#camera-select", "change");
    await page.waitForTimeout(300);

    step("query");
    const reference = await canvasPixels(page, "#view3d");
    await page.fill("#query-text", "green");
    await page.selectOption("#query-granularity", "small");
    await page.click("#query-run");
    await page.locator(`#query-results li[data-object-id="${GREEN_OBJECT}"]`).waitFor();
    await page.waitForFunction((id) => document.getElementById("view3d").dataset.selected === String(id)
      && Number(document.getElementById("view3d").dataset.masks) >= 1, GREEN_OBJECT);
    await page.waitForTimeout(300);
    const answer = await page.textContent("#query-results");
    assert.ok(/score [0-9.-]+, relevancy [0-9.]+/.test(answer), answer);
    const after = await canvasPixels(page, "#view3d");
    const box = await page.evaluate((id) => window.segsplatConsole.view.projectedBox(id), GREEN_OBJECT);
    assert.ok(box, "the green object projects into the view");
    const ratio = after.width / after.cssWidth;
    const pixelBox = { x0: box.x0 * ratio, y0: box.y0 * ratio, x1: box.x1 * ratio, y1: box.y1 * ratio };
    const change = insideOutside(after, pixelBox, (i) =>
      Math.abs(after.data[i] - reference.data[i]) + Math.abs(after.data[i + 1] - reference.data[i + 1]) + Math.abs(after.data[i + 2] - reference.data[i + 2]));
    const brightness = (image) => (i) => image.data[i] + image.data[i + 1] + image.data[i + 2];
    const litBefore = insideOutside(reference, pixelBox, brightness(reference));
    const litAfter = insideOutside(after, pixelBox, brightness(after));
    console.log(`   box ${JSON.stringify(pixelBox)} change inside ${change.inside.toFixed(1)} outside ${change.outside.toFixed(1)}; brightness inside/outside before ${(litBefore.inside / Math.max(1, litBefore.outside)).toFixed(2)} after ${(litAfter.inside / Math.max(1, litAfter.outside)).toFixed(2)}`);
    assert.ok(change.inside > 10, `the view changes where the object is (mean change ${change.inside})`);
    assert.ok(litAfter.inside / Math.max(1, litAfter.outside) > 1.5 * (litBefore.inside / Math.max(1, litBefore.outside)),
      "the object stands out from the rest after the query");

    step("mask overlay");
    const overlay = await canvasPixels(page, "#mask-overlay");
    const masked = insideOutside(overlay, pixelBox, (i) => (overlay.data[i + 3] > 0 ? 1 : 0));
    assert.ok(masked.inside > 0.05, `the mask covers the object's box (${masked.inside})`);
    assert.ok(masked.inside > 5 * masked.outside, `the mask lies on the object (${JSON.stringify(masked)})`);
    await page.locator("#view-panel").scrollIntoViewIfNeeded();
    await shot(page, "05-query-green");

    step("visible-only masks");
    // Wait for this query's own answer, not the masks the last one left: an answer still on its
    // way when the next query is asked must not be taken for it.
    const answeredBefore = await page.evaluate(() => Number(document.getElementById("query-results").dataset.answered || 0));
    await page.check("#query-visible");
    await page.click("#query-run");
    await page.waitForFunction((before) => Number(document.getElementById("query-results").dataset.answered || 0) > before
      && Number(document.getElementById("view3d").dataset.masks) >= 1, answeredBefore);
    await page.uncheck("#query-visible");

    step("nothing matches");
    await page.fill("#query-text", "a chair");
    await page.click("#query-run");
    await page.locator("#query-nothing").waitFor();
    await page.waitForFunction(() => document.getElementById("view3d").dataset.selected === "");

    step("objects");
    await page.hover(`#object-list tr[data-object-id="1"]`);
    await page.waitForFunction(() => document.getElementById("view3d").dataset.selected === "1");
    const downloadEvent = page.waitForEvent("download");
    await page.click(`#object-list tr[data-object-id="${GREEN_OBJECT}"] button.download`);
    const downloaded = await downloadEvent;
    const plyPath = path.join(env("SEGSPLAT_DOWNLOADS"), downloaded.suggestedFilename());
    await downloaded.saveAs(plyPath);
    const ply = readFileSync(plyPath);
    assert.equal(ply.subarray(0, 4).toString(), "ply\n", "the download is a PLY");
    assert.ok(ply.toString("latin1").includes("element vertex"), "with vertices");

    step("phone");
    await page.setViewportSize({ width: 390, height: 844 });
    await page.waitForTimeout(300);
    const overflow = await page.evaluate(() => document.documentElement.scrollWidth - window.innerWidth);
    const wide = await page.evaluate(() => [`body ${document.body.scrollWidth}`, ...[...document.querySelectorAll("body *")]
      .map((node) => [node.getBoundingClientRect().right, node])
      .sort((a, b) => b[0] - a[0]).slice(0, 6)
      .map(([right, node]) => `${node.tagName.toLowerCase()}#${node.id}.${node.className}@${Math.round(right)}<${node.parentElement.tagName.toLowerCase()}#${node.parentElement.id}`)]);
    assert.ok(overflow <= 1, `nothing overflows a phone-sized viewport (${overflow}px): ${wide.join(" ")}`);
    await shot(page, "06-phone");
    await page.setViewportSize({ width: 1280, height: 800 });

    step("status");
    await page.click("#nav-status");
    await page.locator("#queue-list tr").first().waitFor();
    assert.ok(await page.locator("#grafana-link").isVisible(), "the Grafana link is shown when configured");
    const ready = await page.textContent("#status-facts");
    assert.ok(ready.includes("Workers"), ready);
    // With the token the page gets /readyz's details (without one, /readyz says only whether
    // the service is ready).
    assert.ok(!ready.includes("details need a token"), ready);
    assert.ok(ready.includes("reachable"), ready);
    // Workers are alive here: no warning. Jobs queued with no live worker warn (issue 41: the
    // page said "Ready: yes" and nothing else), whatever readiness says.
    assert.ok(await page.locator("#status-warning").isHidden(), "no warning while workers are alive");
    const warnings = await page.evaluate(async () => {
      const { queueWarning } = await import("/console/status.js");
      const series = (pairs) => pairs.map(([state, value]) => [{ state }, value]);
      return [
        queueWarning(series([["queued", 2], ["running", 0]]), series([["busy", 0], ["idle", 0], ["silent", 1]])),
        queueWarning(series([["queued", 2]]), series([["busy", 0], ["idle", 1], ["silent", 0]])),
        queueWarning(series([["queued", 0]]), series([["busy", 0], ["idle", 0], ["silent", 0]])),
      ];
    });
    assert.ok(warnings[0].startsWith("2 jobs queued and no worker is alive (1 silent"), warnings[0]);
    assert.deepEqual(warnings.slice(1), ["", ""]);
    await shot(page, "07-status");

    step("delete running");
    await page.click("#nav-scenes");
    const sceneId = await page.locator("#scene-list tr").first().getAttribute("data-scene-id");
    const long = await api("POST", `/v1/scenes/${sceneId}/jobs`, { kind: "reconstruct", config: { steps: 100000 } });
    assert.equal(long.status, 201, JSON.stringify(long.body));
    await page.click(`#scene-list tr[data-scene-id="${sceneId}"] button.delete`);
    await page.locator("#scenes-error").filter({ hasText: "409" }).waitFor();
    await shot(page, "08-delete-refused");

    step("cancel");
    await page.click(`#scene-list tr[data-scene-id="${sceneId}"]`);
    await page.waitForFunction(() => ["queued", "running"].includes(document.getElementById("job-live").dataset.state));
    await page.click("#job-cancel");
    await page.waitForFunction(() => document.getElementById("job-live").dataset.state === "cancelled", null, { timeout: 120_000 });
    await page.locator("#job-error").filter({ hasText: "cancelled" }).waitFor();

    step("delete");
    await page.click("#nav-scenes");
    await page.click(`#scene-list tr[data-scene-id="${sceneId}"] button.delete`);
    await page.locator(`#scene-list tr[data-scene-id="${sceneId}"]`).waitFor({ state: "detached" });

    step("failed job");
    await page.setInputFiles("#upload-input", env("SEGSPLAT_NO_MASKS_ZIP"));
    await page.locator("#upload-result").filter({ hasText: "no-masks" }).waitFor();
    await page.click("#scene-list tr >> nth=0");
    await page.locator("#view-status").filter({ hasText: "Not trained yet" }).waitFor();
    await page.selectOption("#job-kind", "segment_then_splat");
    await page.fill("#job-steps", "20");
    await page.selectOption("#job-masks", "user");
    await page.click("#job-start");
    await page.waitForFunction(() => document.getElementById("job-live").dataset.state === "failed", null, { timeout: 120_000 });
    const reason = await page.textContent("#job-error");
    assert.ok(reason.startsWith("The job failed: ") && reason.includes("masks"), `the reason is shown: ${reason}`);
    await shot(page, "09-job-failed");

    step("dynamic");
    // Trained through the API with a shortened schedule (the form offers the common options
    // only); the console then moves it in time.
    const moving = (await uploadArchive(env("SEGSPLAT_DYNAMIC_ZIP"), "moving")).body;
    const dynamicJob = await api("POST", `/v1/scenes/${moving.id}/jobs`, {
      kind: "segment_then_splat",
      config: {
        steps: DYNAMIC_STEPS, checkpoint_every: 0, masks: "user", max_gaussians: 4000,
        random_init_count: 2000, background_shell: 200, max_sh_degree: 0,
        object_loss: { middle_from: 1.0, large_from: 1.0 },
        deformation: { field: { depth: 4, width: 64, skip_after: 2 }, warm_up_steps: 50, learning_rate_decay_steps: 40000 },
      },
    });
    assert.equal(dynamicJob.status, 201, JSON.stringify(dynamicJob.body));
    await page.goto(`${base}/#/scenes/${moving.id}`);
    await page.waitForFunction(() => document.getElementById("job-live").dataset.state === "succeeded", null, { timeout: 300_000 });
    await page.locator("#view-status").filter({ hasText: "Gaussians" }).waitFor({ timeout: 60_000 });
    assert.ok(await page.locator("#time-slider").isVisible(), "a dynamic scene has a time slider");
    await page.fill("#query-text", "green");
    await page.selectOption("#query-granularity", "small");
    await page.click("#query-run");
    await page.waitForFunction(() => Number(document.getElementById("view3d").dataset.masks) >= 1);
    await page.waitForTimeout(300);
    const atStart = await canvasPixels(page, "#view3d");
    const masksAtStart = await canvasPixels(page, "#mask-overlay");
    await page.locator("#view-panel").scrollIntoViewIfNeeded();
    await shot(page, "10-dynamic-t0");
    await page.locator("#time-slider").fill("1");
    await page.dispatchEvent("#time-slider", "change");
    await page.waitForFunction(() => document.getElementById("view3d").dataset.time === "1"
      && Number(document.getElementById("view3d").dataset.masks) >= 1);
    await page.waitForTimeout(500);
    const atEnd = await canvasPixels(page, "#view3d");
    const masksAtEnd = await canvasPixels(page, "#mask-overlay");
    const meanChange = (a, b, channels) => {
      let total = 0;
      for (let i = 0; i < a.data.length; i += 4) for (const c of channels) total += Math.abs(a.data[i + c] - b.data[i + c]);
      return total / (a.data.length / 4);
    };
    const moved = meanChange(atStart, atEnd, [0, 1, 2]);
    const masksMoved = meanChange(masksAtStart, masksAtEnd, [3]);
    console.log(`   time 0 -> 1: mean view change ${moved.toFixed(2)}, mean mask change ${masksMoved.toFixed(2)}`);
    assert.ok(moved > 1, `the Gaussians move with time (${moved})`);
    assert.ok(masksMoved > 1, `the masks move with time (${masksMoved})`);
    await shot(page, "11-dynamic-t1");

    step("console errors");
    assert.deepEqual(consoleErrors, [], "the console logged no errors");
  } catch (error) {
    await shot(page, `failed-${phase.replace(/\W+/g, "-")}`).catch(() => {});
    console.error(`console e2e failed at "${phase}":`, error);
    console.error(`view status: ${await page.textContent("#view-status").catch(() => "?")}`);
    if (consoleErrors.length) console.error("console errors:", consoleErrors);
    process.exitCode = 1;
  } finally {
    await browser.close();
  }
}

await main();
