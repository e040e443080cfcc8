#!/usr/bin/env python3
"""Measures, in headless Chromium at a 1280 px wide window, whether every table of a page fits.

Usage: table_widths.py [--width PX] [--tables CLASS,...] CHROMIUM PROFILE_DIR URL...

For each URL, prints one line per table: its classes, its width and the width its container
offers (the .table-wrap that would scroll it sideways, else the page), "ok" or "SCROLLS". Exits 1
when a table is wider than its container or the page itself scrolls sideways, 2 when Chromium
cannot be driven. --width sets the window's width (a phone: 400); --tables checks only tables
with one of those classes (the others may scroll in their .table-wrap) and also that every
status or verdict badge (.badge) inside them is laid out wholly inside the window, so that
nothing hides a verdict off to the side. Chromium is driven over the DevTools protocol on a pipe
(--remote-debugging-pipe: JSON messages separated by NUL bytes, commands on fd 3, answers on
fd 4), so no port is opened and nothing but the standard library is needed.
"""
import fcntl
import json
import os
import subprocess
import sys
import time

WIDTH, HEIGHT = 1280, 2400  # --width changes WIDTH

MEASURE = r"""
(() => {
  const out = {page: document.documentElement.scrollWidth, window: window.innerWidth, tables: []};
  for (const t of document.querySelectorAll('table')) {
    const wrap = t.closest('.table-wrap');
    const room = wrap ? wrap.clientWidth : document.documentElement.clientWidth;
    // The table's own laid-out width against the room its container offers (a wrap's
    // scrollWidth would also blame a narrow table for a wide neighbour in the same wrap).
    const width = Math.ceil(t.getBoundingClientRect().width);
    const badges = [];
    for (const b of t.querySelectorAll('.badge')) {
      const r = b.getBoundingClientRect();
      const shown = r.width > 0 && r.height > 0 && r.left >= -1 && r.right <= window.innerWidth + 1;
      badges.push({text: b.textContent, shown: shown, left: Math.round(r.left),
                   right: Math.round(r.right)});
    }
    out.tables.push({name: t.className || '(no class)', width: width, room: room,
                     scrolls: width > room + 1, badges: badges});
  }
  return JSON.stringify(out);
})()
"""


class Chromium:
    def __init__(self, binary, profile):
        to_chrome_r, self.to_chrome = os.pipe()
        self.from_chrome, from_chrome_w = os.pipe()
        # The child must see the pipe ends as fds 3 (commands in) and 4 (answers out): moved out
        # of the way first (a pipe end may itself be fd 3 or 4), then into place; pass_fds keeps
        # 3 and 4 open through the exec.
        def child_fds():
            commands = fcntl.fcntl(to_chrome_r, fcntl.F_DUPFD, 10)
            answers = fcntl.fcntl(from_chrome_w, fcntl.F_DUPFD, 10)
            os.dup2(commands, 3)
            os.dup2(answers, 4)
        self.proc = subprocess.Popen(
            [binary, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--hide-scrollbars", "--remote-debugging-pipe", "--user-data-dir=" + profile,
             "--window-size=%d,%d" % (WIDTH, HEIGHT), "about:blank"],
            pass_fds=(3, 4), preexec_fn=child_fds,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(to_chrome_r)
        os.close(from_chrome_w)
        self.buffer = b""
        self.next_id = 0

    def call(self, method, params=None, session=None, timeout=60):
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params or {}}
        if session:
            message["sessionId"] = session
        os.write(self.to_chrome, json.dumps(message).encode() + b"\0")
        deadline = time.time() + timeout
        while True:
            while b"\0" in self.buffer:
                raw, self.buffer = self.buffer.split(b"\0", 1)
                answer = json.loads(raw)
                if answer.get("id") == self.next_id:
                    if "error" in answer:
                        raise RuntimeError("%s: %s" % (method, answer["error"]))
                    return answer.get("result", {})
            if time.time() > deadline:
                raise RuntimeError(method + ": no answer from Chromium")
            chunk = os.read(self.from_chrome, 1 << 16)
            if not chunk:
                raise RuntimeError(method + ": Chromium closed the pipe")
            self.buffer += chunk

    def close(self):
        try:
            self.call("Browser.close", timeout=10)
        except RuntimeError:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def measure(chromium, url):
    target = chromium.call("Target.createTarget", {"url": "about:blank"})["targetId"]
    session = chromium.call("Target.attachToTarget",
                            {"targetId": target, "flatten": True})["sessionId"]
    chromium.call("Emulation.setDeviceMetricsOverride",
                  {"width": WIDTH, "height": HEIGHT, "deviceScaleFactor": 1, "mobile": False},
                  session)
    chromium.call("Page.navigate", {"url": url}, session)
    for _ in range(600):
        state = chromium.call("Runtime.evaluate",
                              {"expression": "location.href + ' ' + document.readyState",
                               "returnByValue": True}, session)["result"]["value"]
        if state == url + " complete":
            break
        time.sleep(0.05)
    else:
        raise RuntimeError(url + " did not finish loading")
    value = chromium.call("Runtime.evaluate", {"expression": MEASURE, "returnByValue": True},
                          session)["result"]["value"]
    chromium.call("Target.closeTarget", {"targetId": target})
    return json.loads(value)


def main():
    global WIDTH
    args = sys.argv[1:]
    only = None
    while args and args[0].startswith("--"):
        if args[0] == "--width" and len(args) > 1:
            WIDTH = int(args[1])
        elif args[0] == "--tables" and len(args) > 1:
            only = set(args[1].split(","))
        else:
            print(__doc__.strip().splitlines()[2])
            return 2
        args = args[2:]
    if len(args) < 3:
        print(__doc__.strip().splitlines()[2])
        return 2
    chromium = Chromium(args[0], args[1])
    failed = False
    checked = 0
    try:
        for url in args[2:]:
            m = measure(chromium, url)
            page_scrolls = m["page"] > m["window"] + 1
            print("%s: page %d px in a %d px window%s" %
                  (url, m["page"], m["window"], " SCROLLS" if page_scrolls else ""))
            failed = failed or page_scrolls
            for t in m["tables"]:
                if only is not None and not only & set(t["name"].split()):
                    continue
                checked += 1
                print("  table.%s: %d px in %d px %s" %
                      (t["name"].replace(" ", "."), t["width"], t["room"],
                       "SCROLLS" if t["scrolls"] else "ok"))
                failed = failed or t["scrolls"]
                if only is None:
                    continue
                for b in t["badges"]:
                    if not b["shown"]:
                        print("    badge '%s' at %d..%d px: HIDDEN" %
                              (b["text"], b["left"], b["right"]))
                        failed = True
        if only is not None and checked == 0:
            print("table_widths: no table of class %s on these pages" % ",".join(sorted(only)))
            failed = True
    except RuntimeError as e:
        print("table_widths: " + str(e))
        return 2
    finally:
        chromium.close()
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
