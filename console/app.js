// The console's entry: the token, the pages and the hash routes between them
// (#/scenes, #/scenes/{id}, #/status).

import { getJson, onUnauthorized, request, setToken, token } from "./api.js";
import { $, describeError, showError } from "./dom.js";
import { ScenesPage } from "./scenes.js";
import { ScenePage } from "./scene_view.js";
import { StatusPage } from "./status.js";

const pages = {
  scenes: { element: $("scenes-page"), page: new ScenesPage() },
  scene: { element: $("scene-page"), page: new ScenePage() },
  status: { element: $("status-page"), page: new StatusPage() },
};
let settings = { auth_required: false, grafana_url: null };
let current = null;

function askForToken(message) {
  for (const { element } of Object.values(pages)) element.hidden = true;
  current?.page.leave?.();
  current = null;
  $("token-panel").hidden = false;
  showError($("token-error"), message);
  $("token-input").value = "";
  $("token-input").focus();
}

// Whether the stored token opens the API (a cheap authenticated call).
async function tokenAccepted() {
  try {
    await request("/v1/scenes", { method: "GET" });
    return true;
  } catch (error) {
    if (error.status === 401) return false;
    throw error;
  }
}

function route() {
  if (!$("token-panel").hidden) return;
  const [, name = "scenes", id] = (location.hash || "#/scenes").split("/");
  const target = name === "scenes" && id ? "scene" : pages[name] ? name : "scenes";
  if (current && current !== pages[target]) current.page.leave?.();
  for (const [key, { element }] of Object.entries(pages)) element.hidden = key !== target;
  const [active, inactive] = target === "status" ? ["nav-status", "nav-scenes"] : ["nav-scenes", "nav-status"];
  $(active).setAttribute("aria-current", "page");
  $(inactive).removeAttribute("aria-current");
  current = pages[target];
  current.page.enter(decodeURIComponent(id || ""), settings);
}

async function start() {
  try {
    settings = await getJson("/console/config.json");
  } catch (error) {
    showError($("token-error"), `could not read the console's settings: ${describeError(error)}`);
  }
  onUnauthorized((failure) =>
    askForToken(`The server refused the token (${failure.status}): ${failure.message}`),
  );
  $("token-form").addEventListener("submit", async (event) => {
    event.preventDefault();
    setToken($("token-input").value.trim());
    try {
      if (await tokenAccepted()) {
        $("token-panel").hidden = true;
        showError($("token-error"), "");
        route();
      }
    } catch (error) {
      showError($("token-error"), describeError(error));
    }
  });
  $("token-change").addEventListener("click", () => askForToken(""));
  $("token-change").hidden = !settings.auth_required;
  window.addEventListener("hashchange", route);
  if (settings.auth_required && !token()) return askForToken("");
  if (settings.auth_required && !(await tokenAccepted())) return;
  route();
}

start();
