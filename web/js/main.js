// Wiring of the viewer page: token entry, hash routes (#/jobs, #/view/<id>, #/compare/<a>/<b>) and the
// three panels.

import { Api, loadToken, saveToken } from "./api.js";
import { JobsPanel } from "./jobs.js";
import { ImageViewer } from "./viewer.js";
import { mountCompare } from "./compare.js";

const api = new Api("");
const errorBox = document.querySelector("#error");

function showError(error) {
  errorBox.textContent = String(error?.message || error);
  errorBox.hidden = false;
}

function clearError() {
  errorBox.hidden = true;
  errorBox.textContent = "";
}

const tokenInput = document.querySelector("#token");
tokenInput.value = loadToken();
document.querySelector("#token-form").addEventListener("submit", (event) => {
  event.preventDefault();
  saveToken(tokenInput.value.trim());
  clearError();
  start().catch(showError);
});

const jobs = new JobsPanel(document.querySelector("#jobs-panel"), api, {
  onView: (id) => (window.location.hash = `#/view/${id}`),
  onCompare: (a, b) => (window.location.hash = `#/compare/${a}/${b}`),
  onError: showError,
});
const viewer = new ImageViewer(document.querySelector("#viewer-panel"), api, { onError: showError });
let compareView = null;

async function route() {
  clearError();
  const [, page, a, b] = window.location.hash.split("/");
  const panels = { jobs: "#jobs-panel", view: "#viewer-panel", compare: "#compare-panel" };
  const active = panels[page] ? page : "jobs";
  for (const [name, selector] of Object.entries(panels)) document.querySelector(selector).hidden = name !== active;
  for (const link of document.querySelectorAll("nav a")) {
    if (link.dataset.page === active) link.setAttribute("aria-current", "page");
    else link.removeAttribute("aria-current");
  }
  if (active === "view" && a && a !== viewer.jobId) await viewer.open(a);
  if (active === "compare" && a && b) {
    compareView?.destroy();
    compareView = await mountCompare(document.querySelector("#compare-mount"), { leftJobId: a, rightJobId: b, api });
  }
}

async function start() {
  await Promise.all([jobs.loadExamples(), jobs.refresh()]);
  await route();
}

window.addEventListener("hashchange", () => route().catch(showError));
start().catch(showError);
