// Job list (name · short id, created, size, spp, status, live progress and ETA over SSE, duration,
// samples/s, cancel/delete; regression jobs hidden on request) and the submit form (upload a JSON/USD
// scene or pick an example; override spp, resolution, modes, chunks).

const FINAL = new Set(["succeeded", "failed", "canceled"]);
// hgcore/jobs/views.py: an unfinished job's progress stops at 0.999 until its merge step has run.
export const MERGING_PROGRESS = 0.999;
const MAX_STREAMS = 4; // browsers allow ~6 HTTP/1.1 connections per host; leave room for data requests
// service/regression/runs.py names the render jobs of a run "regression <scene> (run <id>)".
const REGRESSION_NAME = /^regression \S+ \(run [0-9a-f]{8}\)$/;

/** Is this one of a regression run's render jobs? */
export function isRegressionJob(job) {
  return REGRESSION_NAME.test(job.name || "");
}

/** "3 min 20 s" style duration. */
export function formatDuration(seconds) {
  if (seconds == null || !Number.isFinite(seconds)) return "—";
  if (seconds < 60) return `${seconds.toFixed(seconds < 10 ? 1 : 0)} s`;
  const minutes = Math.floor(seconds / 60);
  if (minutes < 60) return `${minutes} min ${Math.round(seconds % 60)} s`;
  return `${Math.floor(minutes / 60)} h ${minutes % 60} min`;
}

/** 3 significant digits with an SI prefix: 327k, 1.24M (short enough for the list's rate column). */
export function formatSi(value) {
  const prefixes = ["", "k", "M", "G", "T"];
  let power = 0;
  while (Math.abs(value) >= 999.5 && power < prefixes.length - 1) {
    value /= 1000;
    power += 1;
  }
  return `${Number(value.toPrecision(3))}${prefixes[power]}`;
}

/** Seconds the job has run (to now while running). */
export function jobDurationS(job, nowS = Date.now() / 1000) {
  const t = job.timings || {};
  if (t.total_s != null && FINAL.has(job.status)) return t.total_s;
  if (t.started_at == null) return null;
  return (t.finished_at ?? nowS) - t.started_at;
}

/** Samples per second of the finished chunks (Σ samples / Σ chunk seconds; null before any). */
export function samplesPerSecond(job) {
  let samples = 0;
  let seconds = 0;
  for (const chunk of job.chunks || []) {
    if (chunk.samples != null && chunk.seconds) {
      samples += chunk.samples;
      seconds += chunk.seconds;
    }
  }
  return seconds > 0 ? samples / seconds : null;
}

/**
 * The jobs panel. `onView(id)` opens the viewer, `onCompare(a, b)` the compare view.
 */
export class JobsPanel {
  constructor(root, api, { onView, onCompare, onError }) {
    this.root = root;
    this.api = api;
    this.onView = onView;
    this.onCompare = onCompare;
    this.onError = onError;
    this.jobs = new Map();
    this.streams = new Map();
    this.selected = [];
    this.table = root.querySelector("#job-rows");
    this.form = root.querySelector("#submit-form");
    this.form.addEventListener("submit", (event) => {
      event.preventDefault();
      this.submit().catch((error) => this.onError(error));
    });
    root.querySelector("#refresh-jobs").addEventListener("click", () => this.refresh().catch((e) => this.onError(e)));
    root.querySelector("#hide-regression").addEventListener("change", () => this.render());
    root.querySelector("#compare-selected").addEventListener("click", () => {
      if (this.selected.length === 2) this.onCompare(this.selected[0], this.selected[1]);
    });
    this.form.querySelector("#scene-file").addEventListener("change", () => this.updateFormState());
    this.timer = window.setInterval(() => this.refresh().catch(() => {}), 5000);
  }

  async loadExamples() {
    const select = this.form.querySelector("#scene-example");
    const examples = await this.api.json("/v1/examples");
    select.replaceChildren(new Option("— upload a file instead —", ""));
    for (const example of examples) select.append(new Option(`${example.title} (${example.name})`, example.name));
    if (examples.length) select.value = examples[0].name;
    this.examples = examples;
    this.renderGallery(examples.filter((example) => example.figure));
    this.updateFormState();
  }

  /** One button per gallery scene (thumbnail + figure): a click submits it, named after the scene. */
  renderGallery(gallery) {
    const strip = this.form.querySelector("#gallery-examples");
    strip.replaceChildren();
    for (const example of gallery) {
      const button = document.createElement("button");
      button.type = "button";
      button.className = "gallery-example";
      button.dataset.example = example.name;
      button.title = example.title;
      button.setAttribute("aria-label", `render ${example.figure}: ${example.title}`);
      if (example.thumbnail) {
        const image = document.createElement("img");
        image.alt = "";
        image.width = image.height = 64;
        this.api.blobUrl(example.thumbnail).then((url) => (image.src = url)).catch(() => {});
        button.append(image);
      }
      const caption = document.createElement("span");
      caption.textContent = example.figure;
      button.append(caption);
      button.addEventListener("click", () => {
        this.form.querySelector("#scene-example").value = example.name;
        this.form.querySelector("#scene-file").value = "";
        this.form.querySelector("#job-name").value = example.name.replace(/\.json$/, "");
        this.updateFormState();
        this.submit().catch((error) => this.onError(error));
      });
      strip.append(button);
    }
  }

  /** The most telling view of a job rendered from a gallery scene (by its one-click name), else null. */
  galleryView(job) {
    const example = (this.examples || []).find((e) => e.figure && e.name === `${job.name}.json`);
    return example ? example.view : null;
  }

  updateFormState() {
    // Resolution and modes are edited in the scene JSON; a USD upload keeps its own.
    const file = this.form.querySelector("#scene-file").files[0];
    const isUsd = file && !file.name.toLowerCase().endsWith(".json");
    for (const id of ["#override-width", "#override-height", "#override-modes"]) this.form.querySelector(id).disabled = Boolean(isUsd);
  }

  async refresh() {
    const listing = await this.api.json("/v1/jobs?limit=100");
    const seen = new Set();
    for (const job of listing.items) {
      seen.add(job.id);
      this.jobs.set(job.id, job);
    }
    for (const id of [...this.jobs.keys()]) if (!seen.has(id)) this.jobs.delete(id);
    this.render();
    this.followActive();
  }

  followActive() {
    for (const job of this.jobs.values()) {
      if (FINAL.has(job.status) || this.streams.has(job.id) || this.streams.size >= MAX_STREAMS) continue;
      const controller = new AbortController();
      this.streams.set(job.id, controller);
      this.api
        .events(`/v1/jobs/${job.id}/events`, (type, data) => this.onEvent(job.id, type, data), controller.signal)
        .catch(() => {})
        .finally(() => {
          this.streams.delete(job.id);
          this.followActive();
        });
    }
  }

  onEvent(id, type, data) {
    const job = this.jobs.get(id);
    if (!job) return;
    if (type === "status") this.jobs.set(id, data);
    else if (type === "progress") Object.assign(job, { progress: data.progress, chunks_done: data.chunks_done, eta_s: data.eta_s, status: job.status === "queued" ? "running" : job.status });
    this.renderRow(this.jobs.get(id));
  }

  /** The name shown for a job: its name (or "job") and the first 8 hex digits of its id, which tell
   * two jobs of the same scene apart. */
  label(job) {
    return `${job.name || "job"} · ${job.id.slice(0, 8)}`;
  }

  render() {
    const hideRegression = this.root.querySelector("#hide-regression").checked;
    const all = [...this.jobs.values()];
    const shown = all.filter((job) => !(hideRegression && isRegressionJob(job)));
    const hidden = all.length - shown.length;
    this.root.querySelector("#jobs-hidden").textContent = hidden ? `${hidden} regression job${hidden > 1 ? "s" : ""} hidden` : "";
    for (const job of all) if (!shown.includes(job)) this.table.querySelector(`tr[data-job-id="${job.id}"]`)?.remove();
    const ids = shown.sort((a, b) => b.timings.created_at - a.timings.created_at).map((j) => j.id);
    const rows = new Map([...this.table.querySelectorAll("tr[data-job-id]")].map((tr) => [tr.dataset.jobId, tr]));
    for (const [id, tr] of rows) if (!this.jobs.has(id)) tr.remove();
    for (const id of ids) this.renderRow(this.jobs.get(id));
    for (const id of ids) this.table.append(this.table.querySelector(`tr[data-job-id="${id}"]`));
    this.root.querySelector("#jobs-empty").hidden = ids.length > 0;
  }

  renderRow(job) {
    let tr = this.table.querySelector(`tr[data-job-id="${job.id}"]`);
    if (!tr && this.root.querySelector("#hide-regression").checked && isRegressionJob(job)) return;
    if (!tr) {
      tr = document.createElement("tr");
      tr.dataset.jobId = job.id;
      tr.innerHTML = `
        <td><input type="checkbox" class="job-select"></td>
        <td class="job-name"><a class="job-link"></a></td>
        <td class="job-created"></td>
        <td class="job-size"></td>
        <td class="job-spp"></td>
        <td class="job-status"></td>
        <td><progress class="job-progress" max="1" value="0"></progress> <span class="job-percent"></span></td>
        <td class="job-eta"></td>
        <td class="job-duration"></td>
        <td class="job-rate"></td>
        <td class="job-actions">
          <button type="button" class="job-view">View</button>
          <button type="button" class="job-cancel">Cancel</button>
          <button type="button" class="job-delete">Delete</button>
        </td>`;
      const label = this.label(job);
      tr.querySelector(".job-select").setAttribute("aria-label", `select ${label} for comparison`);
      tr.querySelector(".job-progress").setAttribute("aria-label", `progress of ${label}`);
      tr.querySelector(".job-select").addEventListener("change", (event) => this.toggleSelected(job.id, event.target.checked));
      tr.querySelector(".job-view").addEventListener("click", () => this.onView(job.id));
      tr.querySelector(".job-cancel").addEventListener("click", () => this.cancel(job.id).catch((e) => this.onError(e)));
      tr.querySelector(".job-delete").addEventListener("click", () => this.remove(job.id).catch((e) => this.onError(e)));
      this.table.append(tr);
    }
    // The name links to the job's image (as View does); a long one is cut, its tooltip has all of it.
    const link = tr.querySelector(".job-link");
    link.textContent = this.label(job);
    link.href = `#/view/${job.id}`;
    link.title = `${job.name || "job"} (${job.id}): open in the image view`;
    const created = new Date(job.timings.created_at * 1000);
    tr.querySelector(".job-created").textContent = created.toLocaleString(undefined, { month: "short", day: "numeric", hour: "2-digit", minute: "2-digit", second: "2-digit", hourCycle: "h23" });
    tr.querySelector(".job-created").title = created.toISOString();
    tr.querySelector(".job-size").textContent = job.width && job.height ? `${job.width}×${job.height}` : "—";
    tr.querySelector(".job-spp").textContent = String(job.spp);
    tr.querySelector(".job-eta").textContent = job.status === "running" && job.eta_s != null ? formatDuration(job.eta_s) : job.status === "queued" ? "queued" : "—";
    const status = tr.querySelector(".job-status");
    status.textContent = job.status + (job.error ? ` (${job.error})` : "");
    status.title = status.textContent;
    status.className = `job-status status-${job.status}`;
    tr.dataset.status = job.status;
    tr.querySelector(".job-progress").value = job.progress;
    tr.querySelector(".job-percent").textContent = progressText(job);
    const duration = jobDurationS(job);
    tr.querySelector(".job-duration").textContent = formatDuration(duration);
    const rate = samplesPerSecond(job);
    tr.querySelector(".job-rate").textContent = rate == null ? "—" : formatSi(rate);
    tr.querySelector(".job-rate").title = rate == null ? "" : `${Math.round(rate)} samples per second`;
    // A running job can be previewed once a chunk (a noise-target job: a round) has finished (the API
    // merges the finished chunks' partials).
    tr.querySelector(".job-view").disabled = !(job.status === "succeeded" || (job.status === "running" && previewRevision(job) > 0));
    tr.querySelector(".job-cancel").disabled = FINAL.has(job.status);
  }

  toggleSelected(id, on) {
    this.selected = this.selected.filter((x) => x !== id);
    if (on) this.selected.push(id);
    while (this.selected.length > 2) {
      const dropped = this.selected.shift();
      const box = this.table.querySelector(`tr[data-job-id="${dropped}"] .job-select`);
      if (box) box.checked = false;
    }
    this.root.querySelector("#compare-selected").disabled = this.selected.length !== 2;
  }

  async cancel(id) {
    this.jobs.set(id, await this.api.json(`/v1/jobs/${id}/cancel`, { method: "POST" }));
    this.renderRow(this.jobs.get(id));
  }

  async remove(id) {
    if (!window.confirm(`Delete job ${id} and its artifacts?`)) return;
    await this.api.json(`/v1/jobs/${id}`, { method: "DELETE" });
    this.streams.get(id)?.abort();
    this.jobs.delete(id);
    this.render();
  }

  /** Build the request from the form and POST it; returns the new job's id. */
  async submit() {
    const form = this.form;
    const number = (id) => (form.querySelector(id).value === "" ? null : Number(form.querySelector(id).value));
    const options = { spp: number("#override-spp"), chunks: number("#override-chunks") };
    const name = form.querySelector("#job-name").value.trim();
    if (name) options.name = name;
    const file = form.querySelector("#scene-file").files[0];
    const example = form.querySelector("#scene-example").value;
    let created;
    if (file && !file.name.toLowerCase().endsWith(".json")) {
      const body = new FormData();
      body.append("scene", file, file.name);
      for (const [key, value] of Object.entries(options)) if (value != null) body.append(key, String(value));
      created = await this.api.json("/v1/jobs", { method: "POST", body });
    } else {
      let scene;
      if (file) scene = JSON.parse(await file.text());
      else if (example) scene = await this.api.json(`/v1/examples/${encodeURIComponent(example)}`);
      else throw new Error("scene: choose an example or a file");
      scene.film = scene.film || {};
      const overrides = { width: number("#override-width"), height: number("#override-height"), modes: number("#override-modes") };
      for (const [key, value] of Object.entries(overrides)) if (value != null) scene.film[key] = value;
      const body = { scene };
      for (const [key, value] of Object.entries(options)) if (value != null) body[key] = value;
      created = await this.api.postJson("/v1/jobs", body);
    }
    await this.refresh();
    this.root.querySelector("#submit-status").textContent = `submitted ${created.id}`;
    return created.id;
  }
}

/** "42%" (rounded down: 100 % only once the job succeeded), or "merging" while a running job's samples
 * are all rendered and its merge step runs (the service caps a running job's progress at MERGING_PROGRESS). */
export function progressText(job) {
  if (job.status === "running" && job.progress >= MERGING_PROGRESS) return "merging";
  return `${Math.floor(job.progress * 100)}%`;
}

/** How many previews a running job has published: its finished chunks plus its noise-target rounds (a
 * target job replaces its one preview after each round). The viewer refreshes when this changes. */
export function previewRevision(job) {
  return job.chunks_done + (job.noise_target?.rounds?.length ?? 0);
}
