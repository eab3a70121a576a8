"""Opens a report's index.html in a running headless Chromium over the DevTools protocol
(https://chromedevtools.github.io/devtools-protocol/) and checks what a reader sees:

- at 1280 px wide the page has no horizontal overflow, and the first screen holds the summary
  and a video;
- every video loads, plays to its end, decodes frames, and lasts as long as its episode (the
  `data-duration` the report wrote, within a frame and a half); every poster frame loads;
- index.html stays under 500 KB and every GIF the Markdown page shows exists.

Usage: check_report.py PORT REPORT_DIR SCREENSHOT.png
"""
import base64
import itertools
import json
import pathlib
import sys
import time
import urllib.request

import websocket  # websocket-client

PLAY_ALL = r"""
(async () => {
  const results = [];
  for (const v of document.querySelectorAll('video')) {
    const r = {src: v.getAttribute('src'), expected: parseFloat(v.dataset.duration), fps: parseFloat(v.dataset.fps)};
    try {
      v.muted = true;
      if (v.readyState < 1) {
        await new Promise((ok, fail) => {
          v.addEventListener('loadedmetadata', ok, {once: true});
          v.addEventListener('error', () => fail(new Error('error code ' + (v.error && v.error.code))), {once: true});
          v.load();
        });
      }
      r.duration = v.duration;
      v.playbackRate = 16;
      const ended = new Promise(ok => v.addEventListener('ended', ok, {once: true}));
      await v.play();
      await Promise.race([ended, new Promise((_, fail) => setTimeout(() => fail(new Error('did not end in 60 s')), 60000))]);
      r.frames = v.getVideoPlaybackQuality().totalVideoFrames;
      r.decoded = v.webkitDecodedFrameCount;
      r.width = v.videoWidth;
      r.height = v.videoHeight;
    } catch (e) {
      r.error = String(e);
    }
    results.push(r);
  }
  const posters = await Promise.all([...document.querySelectorAll('video')].map(v => new Promise(ok => {
    const img = new Image();
    img.onload = () => ok({src: v.poster, ok: img.naturalWidth > 0});
    img.onerror = () => ok({src: v.poster, ok: false});
    img.src = v.poster;
  })));
  return JSON.stringify({videos: results, posters});
})()
"""

LAYOUT = r"""
JSON.stringify({
  scrollWidth: document.documentElement.scrollWidth,
  innerWidth: window.innerWidth,
  innerHeight: window.innerHeight,
  summaryTop: (() => { const h = [...document.querySelectorAll('h2')].find(h => h.textContent === 'Summary');
                       return h ? h.getBoundingClientRect().top : null; })(),
  firstVideoTop: (() => { const v = document.querySelector('video'); return v ? v.getBoundingClientRect().top : null; })(),
  videos: document.querySelectorAll('video').length,
})
"""


class DevTools:
    def __init__(self, port):
        deadline = time.time() + 30
        while True:
            try:
                targets = json.load(urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list"))
                page = next(t for t in targets if t["type"] == "page")
                break
            except Exception:
                if time.time() > deadline:
                    raise
                time.sleep(0.5)
        self.ws = websocket.create_connection(page["webSocketDebuggerUrl"], timeout=600)
        self.ids = itertools.count(1)

    def call(self, method, **params):
        i = next(self.ids)
        self.ws.send(json.dumps({"id": i, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == i:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def evaluate(self, expression):
        r = self.call("Runtime.evaluate", expression=expression, awaitPromise=True, returnByValue=True)
        if "exceptionDetails" in r:
            raise RuntimeError(f"page script failed: {r['exceptionDetails']}")
        return json.loads(r["result"]["value"])


def main():
    port, report, shot = int(sys.argv[1]), pathlib.Path(sys.argv[2]).resolve(), pathlib.Path(sys.argv[3])
    failures = []
    index = report / "index.html"
    size = index.stat().st_size
    print(f"{index}: {size} bytes")
    if size >= 500_000:
        failures.append(f"index.html is {size} bytes, not under 500 KB")
    readme = (report / "README.md").read_text()
    gifs = [line.split("](", 1)[1].split(")", 1)[0] for line in readme.splitlines() if line.startswith("![") and ".gif)" in line]
    missing = [g for g in gifs if not (report / g).is_file()]
    if missing:
        failures.append(f"README.md shows GIFs that are not there: {missing}")
    print(f"README.md shows {len(gifs)} GIFs")

    tools = DevTools(port)
    tools.call("Emulation.setDeviceMetricsOverride", width=1280, height=900, deviceScaleFactor=1, mobile=False)
    tools.call("Page.enable")
    tools.call("Page.navigate", url=index.as_uri())
    deadline = time.time() + 60
    while tools.evaluate("JSON.stringify(document.readyState)") != "complete":
        if time.time() > deadline:
            failures.append("the page did not finish loading in 60 s")
            break
        time.sleep(0.2)
    layout = tools.evaluate(LAYOUT)
    print(f"layout at 1280 px: {layout}")
    if layout["scrollWidth"] > layout["innerWidth"]:
        failures.append(f"horizontal overflow at 1280 px: the page is {layout['scrollWidth']} px wide")
    if layout["summaryTop"] is None or layout["summaryTop"] > layout["innerHeight"]:
        failures.append("the summary is not on the first screen")
    if layout["videos"] > 0 and (layout["firstVideoTop"] is None or layout["firstVideoTop"] > layout["innerHeight"]):
        failures.append(f"the first video starts at {layout['firstVideoTop']} px, below the first screen")
    png = tools.call("Page.captureScreenshot", format="png")["data"]
    shot.write_bytes(base64.b64decode(png))
    print(f"wrote the first screen to {shot}")

    played = tools.evaluate(PLAY_ALL)
    for v in played["videos"]:
        print(f"  {v}")
        if "error" in v:
            failures.append(f"{v['src']}: {v['error']}")
            continue
        frames = max(v.get("frames") or 0, v.get("decoded") or 0)
        if frames <= 0:
            failures.append(f"{v['src']}: no frames decoded")
        # A frame and a half of slack: the video holds the reset's frame, then one per stride.
        if abs(v["duration"] - v["expected"]) > 1.5 / v["fps"]:
            failures.append(f"{v['src']}: lasts {v['duration']:.3f} s, the episode {v['expected']:.3f} s")
    for p in played["posters"]:
        if not p["ok"]:
            failures.append(f"poster {p['src']} did not load")
    print(f"{len(played['videos'])} videos played, {len(played['posters'])} posters loaded")
    if failures:
        print("FAILED:\n  " + "\n  ".join(failures))
        sys.exit(1)
    print("report checks passed")


if __name__ == "__main__":
    main()
