// Regression dashboard: schedules (create, pause/resume, run now, delete), a schedule's runs with the
// trend per scene of a verdict's quantity and its threshold (GET /v1/schedules/{id}/runs → series), and a
// scene's baseline job against its current job in the viewer's compare view (web/js/compare.js), opened
// at the exposure the run used, so its ΔE₀₀ is the run's.

import { Api, loadToken, saveToken } from "/web/js/api.js";
import { mountCompare } from "/web/js/compare.js";
import { formatValue } from "/web/js/colormap.js";
import { drawPlot } from "/web/js/plot.js";

const api = new Api();
const PALETTE = ["#8ab4f8", "#fdd663", "#81c995", "#f28b82", "#c58af9", "#78d9ec", "#fcad70", "#ff8bcb"];
let selectedScheduleId = null;
let compareView = null;

function showError(error) {
  const box = document.getElementById("error");
  const noToken = !loadToken() || error?.status === 401;
  const hint = noToken ? " — paste an API token above: `hgrender serve` wrote one to <data dir>/admin.token (see the Jobs page)" : "";
  box.textContent = error ? String(error.message || error) + hint : "";
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

// The trend plot shows what a verdict tests: each metric with the threshold it is compared against.
export const TREND_METRICS = {
  delta_e00_p95_excess: { label: "ΔE₀₀ p95 above noise", threshold: "max_delta_e00_p95", unit: "" },
  flip_mean_excess: { label: "ꟻLIP mean above noise", threshold: "max_flip_mean", unit: "" },
  rel_rmse_max: { label: "worst band rel. RMSE (noise-corrected)", threshold: "max_rel_rmse", unit: "" },
};
let trendState = null;

/** Points (time, metric) per scene, one colour each, a failed run's point is a ring; threshold dashed. */
function drawTrend() {
  if (!trendState) return;
  const { series, thresholds } = trendState;
  const key = document.getElementById("trend-metric").value;
  const metric = TREND_METRICS[key];
  const plot = document.getElementById("trend");
  const entries = Object.entries(series).map(([scene, points], index) => ({ scene, colour: PALETTE[index % PALETTE.length], points: points.filter((p) => p[key] != null) }));
  const threshold = thresholds[metric.threshold];
  document.getElementById("trend-caption").textContent =
    `${metric.label} per scene over runs — the quantity the verdict compares with ${metric.threshold} = ${threshold} (dashed); filled: pass, ring: fail`;
  plot.dataset.metric = key;
  if (!entries.some((e) => e.points.length)) {
    plot.replaceChildren();
    document.getElementById("trend-legend").replaceChildren();
    const text = document.createElementNS("http://www.w3.org/2000/svg", "text");
    text.setAttribute("x", 60);
    text.setAttribute("y", 120);
    text.textContent = "no compared runs yet";
    plot.append(text);
    return;
  }
  drawPlot(plot, {
    series: entries.map((e) => ({ id: e.scene, name: e.scene, colour: e.colour, points: e.points.map((p) => [p.at, p[key]]), hollow: (i) => e.points[i].verdict !== "pass" })),
    x: { label: "run started", format: (t) => new Date(t * 1000).toLocaleTimeString() },
    y: { label: metric.label, unit: metric.unit, min: 0 },
    lines: [{ y: threshold, label: `threshold ${metric.threshold} = ${threshold}` }],
    legend: document.getElementById("trend-legend"),
    readout: document.getElementById("trend-readout"),
    readoutText: (t, hits) => `${formatTime(t)}: ${hits.map((h) => `${h.name} ${formatValue(h.point[1])}`).join(", ")}`,
  });
}

async function showCompare(scene, result) {
  const section = document.getElementById("compare-section");
  section.hidden = false;
  const stored = result.metrics?.delta_e00 || {};
  const flip = result.metrics?.flip || {};
  document.getElementById("compare-caption").textContent =
    `${scene}: baseline job ${result.baseline_job_id} (left) vs current job ${result.job_id} (right), at the run's exposure ` +
    `${formatValue(result.metrics?.exposure_ev)} EV. The run stored ΔE₀₀ p95 ${formatValue(stored.p95)} (noise level ${formatValue(stored.p95_noise)}), ` +
    `ꟻLIP mean ${formatValue(flip.mean)} (noise level ${formatValue(flip.mean_noise)}).`;
  if (compareView) compareView.destroy();
  compareView = await mountCompare(document.getElementById("compare"), {
    leftJobId: result.baseline_job_id,
    rightJobId: result.job_id,
    api,
    mode: "de2000",
    ev: result.metrics?.exposure_ev ?? null,
    names: [`baseline v${result.baseline_version}`, "current"],
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
  trendState = { series: runs.series, thresholds: schedule.suite.thresholds };
  drawTrend();
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
          showCompare(result.scene, result).catch(showError),
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
  document.getElementById("trend-metric").addEventListener("change", drawTrend);
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
