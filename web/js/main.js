// Wiring of the viewer page: token entry, hash routes (#/jobs, #/view/<id>, #/compare/<a>/<b>), the
// three panels, page-level keyboard shortcuts with their `?` overlay, and drag and drop of an EXR.

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

/** Without a token (or with one the service refuses) the jobs page says how to get one. */
function showTokenHelp(needed) {
  document.querySelector("#token-help").hidden = !needed;
  if (needed) document.querySelector("#jobs-empty").hidden = true;
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
const uploadedNames = new Map(); // uploaded image id → file name

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
  if (active === "view" && a && a !== viewer.jobId) {
    const job = jobs.jobs.get(a);
    // The first view is the picture; a gallery scene whose most telling view is its coherence ellipses
    // (e.g. the cylinder light's anisotropic ones) opens with them, drawn to stay inside their grid cells.
    const ellipses = Boolean(job && jobs.galleryView(job) === "ellipses");
    await viewer.open(a, { label: uploadedNames.get(a) ?? (job ? jobs.label(job) : undefined), ellipses });
  }
  if (active === "compare" && a && b) await showCompare(a, b);
}

let compareRequest = 0; // the latest compare asked for: an older one still loading is dropped

/**
 * Mount the compare view of a and b in place of whatever was there (a failed compare leaves nothing of
 * the previous pair). Routes can overlap (a hash change while the page still loads): only the latest one
 * mounts, so there is one compare view.
 */
async function showCompare(a, b) {
  const request = ++compareRequest;
  compareView?.destroy();
  compareView = null;
  document.querySelector("#compare-hint").hidden = false;
  const mount = document.querySelector("#compare-mount");
  mount.replaceChildren();
  const names = [a, b].map((id) => jobs.jobs.get(id) && jobs.label(jobs.jobs.get(id)));
  let view;
  try {
    view = await mountCompare(mount, { leftJobId: a, rightJobId: b, api, names });
  } catch (error) {
    if (request === compareRequest) throw error;
    return;
  }
  if (request !== compareRequest) return view.destroy();
  compareView = view;
  document.querySelector("#compare-hint").hidden = true;
}

async function start() {
  if (!loadToken()) {
    showTokenHelp(true);
    return route();
  }
  try {
    await Promise.all([jobs.loadExamples(), jobs.refresh()]);
    showTokenHelp(false);
  } catch (error) {
    if (error.status === 401) showTokenHelp(true);
    throw error;
  }
  await route();
}

// ---- keyboard: tev's keys on the image page, no click on the image needed ------------------------------

const help = document.querySelector("#help");
document.querySelector("#help-button").addEventListener("click", () => help.showModal());
// Keys a focused <select> keeps for itself (opening it, moving through its options).
const SELECT_KEYS = new Set(["ArrowUp", "ArrowDown", "ArrowLeft", "ArrowRight", "Enter", " ", "Home", "End", "PageUp", "PageDown"]);

document.addEventListener("keydown", (event) => {
  if (event.ctrlKey || event.metaKey || event.altKey) return;
  const field = event.target.closest?.("input:not([type=checkbox]):not([type=radio]):not([type=range]), textarea");
  if (field) {
    // Enter commits a field (its change or its form's submit happens first) and Esc leaves it; either
    // way the focus goes back to the page, so that the shortcuts work again at once.
    if (event.key === "Enter" || event.key === "Escape") window.setTimeout(() => field.blur(), 0);
    return;
  }
  if (event.target.tagName === "SELECT" && SELECT_KEYS.has(event.key)) return;
  if (event.key === "?") {
    event.preventDefault();
    if (help.open) help.close();
    else help.showModal();
    return;
  }
  if (help.open || document.querySelector("#viewer-panel").hidden) return;
  if (event.target.type === "range" && event.key.startsWith("Arrow")) return; // sliders keep their arrows
  if (viewer.handleKey(event)) event.preventDefault();
});

// ---- a spectral EXR from disk: dropped anywhere, or chosen in the file field -------------------------

/** Send the file to the service (which decodes EXRs for every view) and open it. */
async function openLocalExr(file) {
  if (!file.name.toLowerCase().endsWith(".exr")) throw new Error(`file: ${file.name} is not an .exr file`);
  const created = await api.json("/v1/images", { method: "POST", body: file, headers: { "Content-Type": "image/x-exr" } });
  uploadedNames.set(created.id, file.name);
  window.location.hash = `#/view/${created.id}`;
}

const dropOverlay = document.querySelector("#drop-overlay");
let dragDepth = 0;
window.addEventListener("dragenter", (event) => {
  if (![...(event.dataTransfer?.types || [])].includes("Files")) return;
  dragDepth += 1;
  dropOverlay.hidden = false;
});
window.addEventListener("dragleave", () => {
  dragDepth = Math.max(0, dragDepth - 1);
  if (!dragDepth) dropOverlay.hidden = true;
});
window.addEventListener("dragover", (event) => event.preventDefault());
window.addEventListener("drop", (event) => {
  event.preventDefault();
  dragDepth = 0;
  dropOverlay.hidden = true;
  const file = event.dataTransfer?.files?.[0];
  if (file) openLocalExr(file).catch(showError);
});
document.querySelector("#exr-file").addEventListener("change", (event) => {
  const file = event.target.files[0];
  if (file) openLocalExr(file).catch(showError);
});

window.addEventListener("hashchange", () => route().catch(showError));
start().catch(showError);
