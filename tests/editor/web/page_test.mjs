// The editor page in a real browser: Debian's Chromium driven by Playwright.
// Starts `phos editor` on a free port, checks what the server must refuse,
// then loads the page: the frame at t = 0 after a late one, two constraints
// placed by clicking the image at two times, their targets edited, the
// solved curves through them, the curve panel's axes and legend, swatches at
// two exposures, the export (named after the object, ke unknown where no
// light reaches), targets of zero refused, the colour picker, a screenshot.
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
  // Under AddressSanitizer (make test) every solve and frame is several times
  // slower than in Release: wait up to 2 minutes for each, not Playwright's 30 s.
  page.setDefaultTimeout(120000);
  const errors = [];
  page.on("pageerror", (error) => errors.push(error.message));
  await page.goto(url);
  await page.waitForFunction(() => window.phos && window.phos.state);
  const timeline = await page.evaluate(() => window.phos.state.timeline);
  // The page shows what the selected object wears: its own material (no
  // preset) and its number of states, not the first preset and 1.
  await page.selectOption("#object", "back wall");
  assert.equal(await page.inputValue("#preset"), "");
  assert.equal(await page.inputValue("#states"), "1");
  const frameAt = (t) => timeline.findIndex((x) => x >= t - 1e-9);

  // The frame shown at t = 0 after a late one is the first t = 0 frame (it
  // came back black: every loop of "play" showed one). Its pixels, as drawn.
  const shown = (f) => page.evaluate(async (f) => {
    window.phos.setFrame(f);
    const image = document.getElementById("view");
    await image.decode();
    const canvas = document.createElement("canvas");
    canvas.width = image.naturalWidth; canvas.height = image.naturalHeight;
    const g = canvas.getContext("2d");
    g.drawImage(image, 0, 0);
    const pixels = g.getImageData(0, 0, canvas.width, canvas.height).data;
    let sum = 0, weighted = 0;
    pixels.forEach((v, i) => { sum += v; weighted = (weighted + v * (i % 65521)) % 2147483647; });
    return { sum, weighted };
  }, f);
  const startFrame = await shown(0);
  const lateFrame = await shown(frameAt(60));
  assert.ok(lateFrame.sum < startFrame.sum, "the lit start is brighter than the glow at 60 s");
  const [again] = await Promise.all([shown(0), page.waitForResponse((r) => r.url().includes("/api/frame?t=0&"))]);
  assert.deepEqual(again, startFrame);

  // Two constraints on the back wall: 5 s and 30 s after the LED goes off (30 s).
  const view = page.locator("#view");
  await page.waitForFunction(() => document.getElementById("view").complete);
  const box = await view.boundingBox();
  const place = async (frame) => {
    // Click only once the frame is shown: under AddressSanitizer a frame
    // takes seconds, and a click on the previous one would pick the wrong time.
    await Promise.all([page.waitForResponse((r) => r.url().includes("/api/frame")),
                       page.evaluate((f) => window.phos.setFrame(f), frame)]);
    await page.waitForFunction(() => document.getElementById("view").complete);
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

  // The curve panel: axis titles with units, tick labels and a legend (the
  // text drawn on the canvas, caught as it is drawn).
  const drawn = await page.evaluate(() => {
    const seen = [], original = CanvasRenderingContext2D.prototype.fillText;
    CanvasRenderingContext2D.prototype.fillText = function (text, ...rest) { seen.push(String(text)); return original.call(this, text, ...rest); };
    window.phos.setFrame(window.phos.state.timeline.length - 1);
    CanvasRenderingContext2D.prototype.fillText = original;
    return seen;
  });
  for (const label of ["time t (s)", "R", "G", "B", "now", "#1", "#2"]) assert.ok(drawn.includes(label), `curve panel lacks '${label}': ${drawn}`);
  assert.ok(drawn.some((t) => /^radiance .*\/ sr/.test(t)), `no radiance axis title with units: ${drawn}`);
  assert.ok(drawn.some((t) => /^target/.test(t)), `no legend entry for targets: ${drawn}`);
  assert.ok(drawn.filter((t) => /^\d+e[-+]\d+$/.test(t)).length >= 2, `no radiance ticks: ${drawn}`);

  // Swatches follow the exposure: target and solved colour through the view's
  // tone map (render::ToneMap, written out again here: Reinhard on BT.709
  // luminance, then the sRGB transfer function).
  const expected = (c, e) => {
    const Y = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2], scale = e / (1 + Math.max(0, e * Y));
    return c.map((v) => { const x = Math.min(1, Math.max(0, v * scale));
      return Math.round(255 * (x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055)); });
  };
  const swatches = () => page.evaluate(() => [...document.querySelectorAll("#constraints tbody tr")].map((row) =>
    ["target", "solved"].map((k) => getComputedStyle(row.querySelector(".swatch." + k)).backgroundColor.match(/\d+/g).map(Number))));
  const setExposure = (e) => page.evaluate((e) => { const x = document.getElementById("exposure"); x.value = String(e); x.dispatchEvent(new Event("change")); }, e);
  const exposure0 = await page.evaluate(() => Number(document.getElementById("exposure").value));
  const at1 = await swatches();
  await setExposure(4 * exposure0);
  const at4 = await swatches();
  for (let i = 0; i < 2; ++i) {
    assert.deepEqual(at1[i], [expected(state.constraints[i].rgb, exposure0), expected(state.constraints[i].predicted, exposure0)]);
    assert.deepEqual(at4[i], [expected(state.constraints[i].rgb, 4 * exposure0), expected(state.constraints[i].predicted, 4 * exposure0)]);
    assert.notDeepEqual(at4[i][0], at1[i][0]);
  }
  await setExposure(exposure0);
  // The view was re-rendered with the solved material (a fresh frame request).
  await page.waitForFunction(() => document.getElementById("view").complete);
  assert.match(await view.getAttribute("src"), /\/api\/frame\?t=/);

  // Export: the download is a phos.material/1 named after the object, whose
  // decay matches the targets' 40% over 25 s.
  await page.selectOption("#object", "back wall");
  const [download] = await Promise.all([page.waitForEvent("download"), page.click("#download button")]);
  assert.equal(download.suggestedFilename(), "back-wall.json");
  const material = JSON.parse(readFileSync(await download.path(), "utf8"));
  assert.equal(material.schema, "phos.material/1");
  assert.equal(material.states.length, 1);
  assert.ok(Math.abs(material.states[0].kr - Math.log(1 / 0.4) / 25) < 0.002, `kr ${material.states[0].kr}`);
  // ke stays unknown (null) where no light reaches: the LED lights only the
  // bands near 405 nm, and the page says which bands are unknown.
  const ke = material.states[0].ke;
  assert.ok(ke.some((v) => v === null) && ke.some((v) => typeof v === "number" && v > 0), `ke ${JSON.stringify(ke)}`);
  const unknownNote = await page.textContent("#unknown-ke");
  assert.match(unknownNote, /ke unknown/);
  assert.equal((unknownNote.match(/\d+(\.\d+)?-\d+(\.\d+)?/g) || []).length, ke.filter((v) => v === null).length);

  // Saving under the working folder works.
  response = await post("/api/export", JSON.stringify({ object: "back wall", path: "edited/back-wall.json" }));
  assert.equal(response.status, 200);
  assert.equal(JSON.parse(readFileSync(join(work, "edited/back-wall.json"), "utf8")).schema, "phos.material/1");

  // A target of zero is refused with its message, and nothing changes: typed
  // in the table, or from a point no light reaches (the left wall in the
  // tall block's shadow, pixel 45, 128).
  const refusedEdit = async (act) => {
    const before = await page.evaluate(() => JSON.stringify(window.phos.state.constraints));
    await page.evaluate(() => { document.getElementById("error").textContent = ""; });
    await act();
    await page.waitForFunction(() => document.getElementById("error").textContent !== "");
    assert.equal(await page.evaluate(() => JSON.stringify(window.phos.state.constraints)), before);
    return page.textContent("#error");
  };
  assert.match(await refusedEdit(() => page.evaluate(() => {
    const row = document.querySelector('#constraints tbody tr[data-index="0"]');
    for (let k = 0; k < 3; ++k) row.querySelector(".rgb" + k).value = "0";
    row.querySelector(".rgb2").dispatchEvent(new Event("change", { bubbles: true }));
  })), /Lambda = 0/);
  assert.equal(await page.evaluate(() => Number(document.querySelector('#constraints tbody tr[data-index="0"] .rgb1').value)),
               Number(targets[0][1].toPrecision(4)));  // the table shows the target again
  assert.match(await refusedEdit(() => view.click({ position: { x: (45 + 0.5) * box.width / 256, y: (128 + 0.5) * box.height / 256 } })),
               /no light reaches/);

  // The colour picker: sRGB as it should look at the current exposure e in,
  // linear radiance out, L = x / (e (1 - Y(x))) with x the decoded colour
  // (the inverse of the tone map above), so the target swatch shows the picked colour.
  const picked = "#4080c0";
  const decode = (v) => v <= 0.04045 ? v / 12.92 : Math.pow((v + 0.055) / 1.055, 2.4);
  const x = [1, 3, 5].map((i) => decode(parseInt(picked.slice(i, i + 2), 16) / 255));
  const Yx = 0.2126 * x[0] + 0.7152 * x[1] + 0.0722 * x[2];
  await setExposure(2 * exposure0);
  const revision = await page.evaluate(() => window.phos.state.revision);
  await page.evaluate((hex) => {
    const input = document.querySelector('#constraints tbody tr[data-index="1"] .pick');
    input.value = hex;
    input.dispatchEvent(new Event("change", { bubbles: true }));
  }, picked);
  await page.waitForFunction((b) => window.phos.state.revision !== b, revision);
  const pickedRgb = await page.evaluate(() => window.phos.state.constraints[1].rgb);
  x.forEach((v, k) => assert.ok(Math.abs(pickedRgb[k] - v / (2 * exposure0 * (1 - Yx))) < 1e-9 * (1 + pickedRgb[k]), `picked ${pickedRgb}`));
  assert.deepEqual((await swatches())[1][0], [0x40, 0x80, 0xc0]);
  await setExposure(exposure0);
  // The second target back as it was, for the screenshot.
  const restored = await page.evaluate(() => window.phos.state.revision);
  await page.evaluate((rgb) => {
    const row = document.querySelector('#constraints tbody tr[data-index="1"]');
    rgb.forEach((v, k) => { row.querySelector(".rgb" + k).value = String(v); });
    row.querySelector(".rgb2").dispatchEvent(new Event("change", { bubbles: true }));
  }, targets[1]);
  await page.waitForFunction((b) => window.phos.state.revision !== b, restored);

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
