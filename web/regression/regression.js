// Regression dashboard: schedules (create, pause/resume, run now, delete), a schedule's runs with the
// trend of ΔE₀₀ p95 per scene (GET /v1/schedules/{id}/runs → series), and a failing scene's baseline job
// against its current job in the viewer's compare view (web/js/compare.js).

import { Api, loadToken, saveToken } from "/web/js/api.js";
import { mountCompare } from "/web/js/compare.js";

const api = new Api();
const PALETTE = ["#8ab4f8", "#fdd663", "#81c995", "#f28b82", "#c58af9", "#78d9ec", "#fcad70", "#ff8bcb"];
const SVG_NS = "http://www.w3.org/2000/svg";
let selectedScheduleId = null;
let compareView = null;

function showError(error) {
  const box = document.getElementById("error");
  box.textContent = error ? String(error.message || error) : "";
  box.hidden = !error;
}

function cell(row, content) {
  const td = row.insertCell();
  if (content instanceof Node) td.append(content);
  else td.textContent = content ?? "";
  return td;
}

function button(label, onClick) {
  const b = document.createElement("button");
  b.type = "button";
  b.textContent = label;
  b.addEventListener("click", () => onClick().catch(showError));
  return b;
}

const formatTime = (unixS) => (unixS ? new Date(unixS * 1000).toLocaleString() : "");

async function loadSchedules() {
  const { items } = await api.json("/v1/schedules");
  const body = document.querySelector("#schedules tbody");
  body.replaceChildren();
  for (const schedule of items) {
    const row = body.insertRow();
    const name = document.createElement("button");
    name.className = "scene-link";
    name.textContent = schedule.name;
    name.addEventListener("click", () => selectSchedule(schedule.id).catch(showError));
    cell(row, name);
    cell(row, schedule.cron ? `${schedule.cron} (${schedule.timezone})` : `every ${schedule.interval_s} s`);
    cell(row, formatTime(schedule.next_run_at));
    cell(row, schedule.paused ? "paused" : "active");
    const actions = document.createElement("span");
    actions.className = "controls";
    const base = `/v1/schedules/${schedule.id}`;
    actions.append(
      button(schedule.paused ? "Resume" : "Pause", async () => {
        await api.postJson(`${base}/${schedule.paused ? "resume" : "pause"}`, {});
        await loadSchedules();
      }),
      button("Run now", async () => {
        await api.postJson(`${base}/run`, {});
        await selectSchedule(schedule.id);
      }),
      button("Delete", async () => {
        await api.json(base, { method: "DELETE" });
        if (selectedScheduleId === schedule.id) document.getElementById("runs-section").hidden = true;
        await loadSchedules();
      }),
    );
    cell(row, actions);
  }
}

async function createSchedule(event) {
  event.preventDefault();
  const value = (id) => document.getElementById(id).value.trim();
  let suite;
  try {
    suite = JSON.parse(value("schedule-suite"));
  } catch (error) {
    throw new Error(`suite: not valid JSON (${error.message})`);
  }
  const body = { name: value("schedule-name"), timezone: value("schedule-timezone") || "UTC", suite };
  if (value("schedule-cron")) body.cron = value("schedule-cron");
  if (value("schedule-interval")) body.interval_s = Number(value("schedule-interval"));
  if (value("schedule-webhook")) body.webhook_url = value("schedule-webhook");
  const created = await api.postJson("/v1/schedules", body);
  await loadSchedules();
  await selectSchedule(created.id);
}

function svg(tag, attributes, parent) {
  const element = document.createElementNS(SVG_NS, tag);
  for (const [key, value] of Object.entries(attributes)) element.setAttribute(key, value);
  parent.append(element);
  return element;
}

/** Points (time, ΔE₀₀ p95) per scene, one colour each; a failed run's point is a ring. */
function drawTrend(series, thresholdP95) {
  const plot = document.getElementById("trend");
  plot.replaceChildren();
  const [width, height, left, bottom, top] = [720, 240, 48, 24, 10];
  const points = Object.values(series).flat().filter((p) => p.delta_e00_p95 !== null);
  const legend = document.getElementById("trend-legend");
  legend.replaceChildren();
  if (!points.length) {
    svg("text", { x: left, y: height / 2 }, plot).textContent = "no compared runs yet";
    return;
  }
  const times = points.map((p) => p.at);
  const [t0, t1] = [Math.min(...times), Math.max(...times)];
  const yMax = Math.max(thresholdP95 ?? 0, ...points.map((p) => p.delta_e00_p95)) * 1.1 || 1;
  const x = (t) => left + ((t - t0) / (t1 - t0 || 1)) * (width - left - 10);
  const y = (v) => height - bottom - (v / yMax) * (height - bottom - top);
  svg("line", { class: "axis", x1: left, y1: height - bottom, x2: width - 10, y2: height - bottom }, plot);
  svg("line", { class: "axis", x1: left, y1: top, x2: left, y2: height - bottom }, plot);
  for (const v of [0, yMax / 2, yMax]) {
    svg("text", { x: 4, y: y(v) + 4 }, plot).textContent = v.toFixed(1);
  }
  svg("text", { x: left, y: height - 6 }, plot).textContent = formatTime(t0);
  svg("text", { x: width - 160, y: height - 6 }, plot).textContent = formatTime(t1);
  if (thresholdP95 !== undefined) {
    svg("line", { class: "threshold", x1: left, x2: width - 10, y1: y(thresholdP95), y2: y(thresholdP95) }, plot);
  }
  Object.entries(series).forEach(([scene, entries], index) => {
    const colour = PALETTE[index % PALETTE.length];
    const compared = entries.filter((p) => p.delta_e00_p95 !== null);
    if (compared.length > 1) {
      const path = compared.map((p) => `${x(p.at).toFixed(1)},${y(p.delta_e00_p95).toFixed(1)}`).join(" ");
      svg("polyline", { points: path, fill: "none", stroke: colour, "stroke-width": 1.5 }, plot);
    }
    for (const p of compared) {
      const failed = p.verdict !== "pass";
      const dot = svg("circle", { cx: x(p.at), cy: y(p.delta_e00_p95), r: 4, stroke: colour, "stroke-width": 2, fill: failed ? "none" : colour }, plot);
      svg("title", {}, dot).textContent = `${scene}: ΔE₀₀ p95 ${p.delta_e00_p95.toFixed(3)} (${p.verdict})`;
    }
    const key = document.createElement("span");
    key.style.color = colour;
    key.textContent = `● ${scene}  `;
    legend.append(key);
  });
}

async function showCompare(scene, baselineJobId, currentJobId) {
  const section = document.getElementById("compare-section");
  section.hidden = false;
  document.getElementById("compare-caption").textContent =
    `${scene}: baseline job ${baselineJobId} (left) vs current job ${currentJobId} (right)`;
  if (compareView) compareView.destroy();
  compareView = await mountCompare(document.getElementById("compare"), {
    leftJobId: baselineJobId,
    rightJobId: currentJobId,
    api,
    mode: "de2000",
  });
  section.scrollIntoView({ behavior: "smooth" });
}

async function selectSchedule(scheduleId) {
  selectedScheduleId = scheduleId;
  const [schedule, runs] = await Promise.all([
    api.json(`/v1/schedules/${scheduleId}`),
    api.json(`/v1/schedules/${scheduleId}/runs?limit=200`),
  ]);
  document.getElementById("runs-section").hidden = false;
  document.getElementById("runs-heading").textContent = `Runs of ${schedule.name}`;
  drawTrend(runs.series, schedule.suite.thresholds.max_delta_e00_p95);
  const body = document.querySelector("#runs tbody");
  body.replaceChildren();
  for (const run of runs.items) {
    const row = body.insertRow();
    cell(row, formatTime(run.created_at));
    cell(row, run.trigger);
    cell(row, run.status).className = `run-status-${run.status}`;
    const scenes = document.createElement("span");
    for (const result of run.scenes) {
      const canCompare = result.verdict && result.baseline_job_id && result.job_id && result.baseline_job_id !== result.job_id;
      const item = document.createElement(canCompare ? "button" : "span");
      item.className = `scene-link verdict-${result.verdict ?? "running"}`;
      item.textContent = `${result.scene}: ${result.verdict ?? "rendering"} `;
      if (canCompare) {
        item.title = "compare with the baseline";
        item.addEventListener("click", () =>
          showCompare(result.scene, result.baseline_job_id, result.job_id).catch(showError),
        );
      }
      scenes.append(item);
    }
    cell(row, scenes);
    cell(row, run.reasons.join("; "));
  }
}

function init() {
  const tokenInput = document.getElementById("token");
  tokenInput.value = loadToken();
  document.getElementById("token-form").addEventListener("submit", (event) => {
    event.preventDefault();
    saveToken(tokenInput.value.trim());
    loadSchedules().then(() => showError(null), showError);
  });
  document.getElementById("schedule-form").addEventListener("submit", (event) => {
    createSchedule(event).then(() => showError(null), showError);
  });
  loadSchedules().catch(showError);
  // Keep next-run times and running runs fresh.
  setInterval(() => {
    loadSchedules().catch(showError);
    if (selectedScheduleId) selectSchedule(selectedScheduleId).catch(showError);
  }, 15000);
}

init();
