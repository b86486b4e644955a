// The editor page in a real browser: Debian's Chromium driven by Playwright.
// Starts `phos editor` on a free port, checks what the server must refuse,
// then loads the page, places two constraints by clicking the image at two
// times, edits their targets, checks that the solved curves pass through
// them, exports the material and takes a screenshot.
//
//   node page_test.mjs PHOS_BINARY FIXTURES_DIR [SCREENSHOT.png]

import { spawn } from "node:child_process";
import { mkdtempSync, readFileSync, rmSync } from "node:fs";
import { tmpdir } from "node:os";
import { join } from "node:path";
import assert from "node:assert/strict";
import { chromium } from "playwright-core";

const [phos, fixtures, screenshot] = process.argv.slice(2);
const work = mkdtempSync(join(tmpdir(), "phos-editor-"));
const server = spawn(phos, ["editor", "--port", "0", "--scene", join(fixtures, "scenes/cornell-phosphor.json"),
                            "--presets", join(fixtures, "materials")], { cwd: work });
let browser;
const cleanup = () => { server.kill(); if (browser) browser.close().catch(() => {}); rmSync(work, { recursive: true, force: true }); };
process.on("exit", () => server.kill());

try {
  const url = await new Promise((resolve, reject) => {
    let text = "";
    server.stdout.on("data", (chunk) => {
      text += chunk;
      const match = text.match(/http:\/\/127\.0\.0\.1:(\d+)\//);
      if (match) resolve(match[0]);
    });
    server.on("exit", (code) => reject(new Error("phos editor exited with " + code)));
    setTimeout(() => reject(new Error("phos editor did not start")), 20000);
  });
  const post = (path, body, headers = {}) =>
    fetch(url + path.slice(1), { method: "POST", headers: { "Content-Type": "application/json", ...headers }, body });

  // What the server refuses, with nothing changed.
  const before = await (await fetch(url + "api/state")).json();
  let response = await post("/api/constraints", '{"x": 128, "y": ');
  assert.equal(response.status, 400);
  assert.match((await response.json()).error, /malformed JSON/);
  response = await post("/api/constraints", JSON.stringify({ x: 1, y: 1, t_s: 1, pad: "x".repeat(100000) }));
  assert.equal(response.status, 413);
  response = await post("/api/constraints", JSON.stringify({ x: 128, y: 60, t_s: 35 }), { Origin: "http://evil.example" });
  assert.equal(response.status, 403);
  response = await post("/api/export", JSON.stringify({ object: "back wall", path: "../outside.json" }));
  assert.equal(response.status, 400);
  assert.match((await response.json()).error, /outside the project's working folder/);
  response = await post("/api/constraints", JSON.stringify({ x: 40, y: 230, t_s: 35 }));  // the plain floor
  assert.equal(response.status, 400);
  assert.match((await response.json()).error, /not phosphorescent/);
  const after = await (await fetch(url + "api/state")).json();
  assert.deepEqual(after.constraints, before.constraints);

  // The page.
  browser = await chromium.launch({ executablePath: "/usr/bin/chromium", args: ["--no-sandbox"] });
  const page = await browser.newPage({ viewport: { width: 1280, height: 820 }, acceptDownloads: true });
  const errors = [];
  page.on("pageerror", (error) => errors.push(error.message));
  await page.goto(url);
  await page.waitForFunction(() => window.phos && window.phos.state);
  const timeline = await page.evaluate(() => window.phos.state.timeline);
  const frameAt = (t) => timeline.findIndex((x) => x >= t - 1e-9);

  // Two constraints on the back wall: 5 s and 30 s after the LED goes off (30 s).
  const view = page.locator("#view");
  await page.waitForFunction(() => document.getElementById("view").complete);
  const box = await view.boundingBox();
  const place = async (frame) => {
    await page.evaluate((f) => window.phos.setFrame(f), frame);
    const count = await page.evaluate(() => window.phos.state.constraints.length);
    await view.click({ position: { x: box.width * 0.5, y: box.height * 0.25 } });
    await page.waitForFunction((n) => window.phos.state.constraints.length === n + 1, count);
  };
  const f1 = frameAt(35), f2 = frameAt(60);
  await place(f1);
  await place(f2);
  // Targets: a cyan-green glow at 35 s, the same colour at 40% by 60 s.
  const first = [0.004, 0.02, 0.012];
  const targets = [first, first.map((v) => 0.4 * v)];
  for (let i = 0; i < 2; ++i) {
    // Set the three channels (moving the focus between inputs would fire a
    // change per channel), then one change event: one edit, one re-solve.
    const before = await page.evaluate(() => window.phos.state.revision);
    await page.evaluate(([index, rgb]) => {
      const row = document.querySelector(`#constraints tbody tr[data-index="${index}"]`);
      rgb.forEach((v, k) => { row.querySelector(".rgb" + k).value = String(v); });
      row.querySelector(".rgb2").dispatchEvent(new Event("change", { bubbles: true }));
    }, [i, targets[i]]);
    await page.waitForFunction((b) => window.phos.state.revision !== b, before);
  }
  const state = await page.evaluate(() => window.phos.state);
  assert.equal(state.constraints.length, 2);
  for (let i = 0; i < 2; ++i) {
    const c = state.constraints[i];
    assert.deepEqual(c.rgb.map((v) => Number(v.toPrecision(6))), targets[i].map((v) => Number(v.toPrecision(6))));
    // The solved curve passes through the target: at the constraint's frame, and as the solver reports it.
    assert.ok(c.relative_error < 0.02, `constraint ${i + 1} misses by ${c.relative_error}: ${JSON.stringify({rgb: c.rgb, predicted: c.predicted, t: c.t_s, all: state.constraints.map((q) => [q.t_s, q.rgb, q.weight, q.kind, q.object])})}`);
    const atFrame = c.curve[i === 0 ? f1 : f2];
    for (let k = 0; k < 3; ++k) assert.ok(Math.abs(atFrame[k] - targets[i][k]) <= 0.03 * Math.max(...targets[i]),
                                          `curve ${i + 1} channel ${k}: ${atFrame[k]} vs ${targets[i][k]}`);
  }
  assert.equal(state.solutions.length, 1);
  assert.equal(state.solutions[0].object, "back wall");
  // The view was re-rendered with the solved material (a fresh frame request).
  await page.waitForFunction(() => document.getElementById("view").complete);
  assert.match(await view.getAttribute("src"), /\/api\/frame\?t=/);

  // Export: the download is a phos.material/1 whose decay matches the targets' 40% over 25 s.
  await page.selectOption("#object", "back wall");
  const [download] = await Promise.all([page.waitForEvent("download"), page.click("#download button")]);
  const material = JSON.parse(readFileSync(await download.path(), "utf8"));
  assert.equal(material.schema, "phos.material/1");
  assert.equal(material.states.length, 1);
  assert.ok(Math.abs(material.states[0].kr - Math.log(1 / 0.4) / 25) < 0.002, `kr ${material.states[0].kr}`);

  // Saving under the working folder works.
  response = await post("/api/export", JSON.stringify({ object: "back wall", path: "edited/back-wall.json" }));
  assert.equal(response.status, 200);
  assert.equal(JSON.parse(readFileSync(join(work, "edited/back-wall.json"), "utf8")).schema, "phos.material/1");

  if (screenshot) {
    // Brighter, to see the glow in the picture; the exposure only scales the view.
    await page.evaluate(() => { const e = document.getElementById("exposure"); e.value = "12"; e.dispatchEvent(new Event("change")); });
    await page.waitForFunction(() => document.getElementById("view").src.includes("exposure=12") && document.getElementById("view").complete);
    await page.screenshot({ path: screenshot });
  }
  assert.deepEqual(errors, []);
  console.log("editor page: ok (" + state.solve_ms.toFixed(1) + " ms per solve)");
  cleanup();
  process.exit(0);
} catch (error) {
  console.error(error);
  cleanup();
  process.exit(1);
}
