// Drive Debian's headless Chromium (playwright-core, no browser download) through the fourd
// viewer page and print one JSON report on stdout; tests/viz/test_viewer_browser.py asserts on it.
//
//   node check_viewer.js URL OUTDIR [--frames 0,5] [--glb-frames 0,2,5] [--file-url FILEURL]
//
// It waits for window.fourdReady, steps frames with window.fourdSetFrame(i), collects console
// errors and page errors, reads pixel statistics of the canvas per frame (window.fourdPixels),
// saves a screenshot per frame into OUTDIR, checks the .glb morph animation when present
// (window.fourdGlbCheck), looks at the video panel's image and outline per frame when there is
// one (window.fourdVideo), presses Play and checks that the frame advances, and optionally
// opens the same page from a file:// URL.
"use strict";
const path = require("path");
const { chromium } = require("playwright-core");

const FLAGS = [
  "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
  "--disable-background-networking", "--disable-component-update", "--disable-sync",
  // WebGL without a GPU: SwiftShader (software) through ANGLE
  "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
];

function arg(name, fallback) {
  const i = process.argv.indexOf(name);
  return i >= 0 ? process.argv[i + 1] : fallback;
}

async function openPage(browser, url, report, tag) {
  const page = await browser.newPage({ viewport: { width: 1100, height: 700 } });
  page.on("console", (msg) => {
    if (msg.type() === "error") report.consoleErrors.push(`${tag}: ${msg.text()}`);
    if (msg.type() === "warning") report.consoleWarnings.push(`${tag}: ${msg.text()}`);
  });
  page.on("pageerror", (err) => report.pageErrors.push(`${tag}: ${err.message}`));
  page.on("requestfailed", (req) => report.failedRequests.push(`${tag}: ${req.url()}`));
  page.on("request", (req) => {
    const u = req.url();
    if (!u.startsWith("http://127.0.0.1") && !u.startsWith("http://localhost") && !u.startsWith("file:") && !u.startsWith("data:") && !u.startsWith("blob:")) {
      report.externalRequests.push(`${tag}: ${u}`);
    }
  });
  await page.goto(url, { waitUntil: "load", timeout: 60000 });
  try {
    await page.waitForFunction(() => window.fourdReady === true || (window.fourdErrors && window.fourdErrors.length > 0), null, { timeout: 60000 });
  } catch (err) {
    report.readyTimeout = `${tag}: ${err.message.split("\n")[0]}`;
  }
  return page;
}

(async () => {
  const url = process.argv[2];
  const outdir = process.argv[3];
  const frames = (arg("--frames", "0") || "0").split(",").map(Number);
  const glbFrames = (arg("--glb-frames", "") || "").split(",").filter((s) => s !== "").map(Number);
  const fileUrl = arg("--file-url", null);
  const report = { consoleErrors: [], consoleWarnings: [], pageErrors: [], failedRequests: [], externalRequests: [],
                   frames: [], glb: [], screenshots: [] };
  const browser = await chromium.launch({ executablePath: process.env.FOURD_CHROMIUM || "/usr/bin/chromium", args: FLAGS, headless: true });
  try {
    report.browserVersion = browser.version();
    const page = await openPage(browser, url, report, "http");
    report.ready = await page.evaluate(() => window.fourdReady === true);
    report.viewerErrors = await page.evaluate(() => window.fourdErrors || []);
    report.info = await page.evaluate(() => window.fourdInfo || null);
    report.webgl = await page.evaluate(() => {
      const c = document.createElement("canvas");
      const gl = c.getContext("webgl2") || c.getContext("webgl");
      if (!gl) return null;
      const ext = gl.getExtension("WEBGL_debug_renderer_info");
      return ext ? gl.getParameter(ext.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    });
    // the side panel: the error legend, the metrics table and how its key names wrap
    report.panel = await page.evaluate(() => {
      const legend = document.getElementById("fourd-error-legend");
      const keys = Array.from(document.querySelectorAll("#fourd-metrics td.fourd-key"));
      const lines = (el) => {  // lines of the cell's own text (the row may be taller)
        const range = document.createRange();
        range.selectNodeContents(el);
        return new Set(Array.from(range.getClientRects()).filter((r) => r.width > 0).map((r) => Math.round(r.top))).size;
      };
      return {
        legendShown: !!legend && !legend.hidden && legend.getBoundingClientRect().height > 0,
        legendTicks: legend ? Array.from(legend.querySelectorAll("#fourd-colorbar-ticks span")).map((s) => s.textContent) : [],
        legendText: legend ? legend.textContent : "",
        metricRows: keys.length,
        metricKeys: keys.map((k) => k.textContent),
        keyLines: keys.map(lines),
        keyWidths: keys.map((k) => k.getBoundingClientRect().width),
      };
    });
    if (report.ready) {
      for (const i of frames) {
        const set = await page.evaluate((k) => window.fourdSetFrame(k), i);
        const pixels = await page.evaluate(() => window.fourdPixels(48));
        const shot = path.join(outdir, `viewer-frame-${i}.png`);
        await page.screenshot({ path: shot });
        report.screenshots.push(shot);
        report.frames.push({ requested: i, set, pixels });
      }
      // the video panel (when the page has one): the image of each frame, loaded, and the
      // mesh's outline drawn over it; then the next camera
      if (await page.evaluate(() => window.fourdVideo && window.fourdVideo() !== null)) {
        report.video = [];
        const look = async () => {
          await page.waitForFunction(() => { const v = window.fourdVideo(); return v.src && v.complete && v.naturalWidth > 0; },
                                     null, { timeout: 10000 }).catch(() => {});
          report.video.push(await page.evaluate(() => window.fourdVideo()));
        };
        for (const i of frames) { await page.evaluate((k) => window.fourdSetFrame(k), i); await look(); }
        if (report.video[0].cameras > 1) { await page.selectOption("#fourd-camera", "1"); await look(); }
        const shot = path.join(outdir, "viewer-video.png");
        await page.screenshot({ path: shot });
        report.screenshots.push(shot);
      }
      for (const i of glbFrames) {
        report.glb.push(await page.evaluate((k) => window.fourdGlbCheck(k), i));
      }
      if (report.info && report.info.frameCount > 1) {
        // slow playback so that the loop cannot wrap back to frame 0 between two looks
        await page.selectOption("#fourd-speed", "0.25");
        await page.evaluate(() => window.fourdSetFrame(0));
        await page.click("#fourd-play");
        try {
          await page.waitForFunction(() => document.getElementById("fourd-frame").value !== "0", null, { timeout: 20000 });
        } catch (err) { /* reported as playedTo 0 */ }
        report.playedTo = await page.evaluate(() => Number(document.getElementById("fourd-frame").value));
        await page.click("#fourd-play");
      }
      // the toggles must not throw; pictures of the options and of the .glb playback
      for (const id of ["#fourd-points", "#fourd-filled", "#fourd-errors", "#fourd-carried"]) {
        if (await page.$eval(id, (el) => !el.disabled)) await page.click(id);
      }
      await page.selectOption("#fourd-texture", "grid");
      await page.evaluate(() => window.fourdSetFrame(Math.floor(window.fourdInfo.frameCount / 2)));
      report.afterToggles = await page.evaluate(() => window.fourdPixels(48).inkFraction);
      let shot = path.join(outdir, "viewer-options.png");
      await page.screenshot({ path: shot });
      report.screenshots.push(shot);
      if (await page.$eval("#fourd-glb", (el) => !el.disabled)) {
        if (await page.$eval("#fourd-errors", (el) => el.checked)) await page.click("#fourd-errors");
        await page.selectOption("#fourd-texture", "checker");
        await page.click("#fourd-glb");
        report.glbInk = await page.evaluate(() => window.fourdPixels(48).inkFraction);
        shot = path.join(outdir, "viewer-glb.png");
        await page.screenshot({ path: shot });
        report.screenshots.push(shot);
      }
    }
    await page.close();
    if (fileUrl) {
      const filePage = await openPage(browser, fileUrl, report, "file");
      report.fileReady = await filePage.evaluate(() => window.fourdReady === true);
      report.fileInk = report.fileReady ? await filePage.evaluate(() => window.fourdPixels(48).inkFraction) : 0;
      await filePage.close();
    }
  } finally {
    await browser.close();
  }
  process.stdout.write(JSON.stringify(report) + "\n");
})().catch((err) => {
  process.stdout.write(JSON.stringify({ fatal: String(err && err.stack ? err.stack : err) }) + "\n");
  process.exit(1);
});
