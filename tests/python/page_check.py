"""Drives Debian's headless Chromium through the DevTools protocol against
the daemon's status page, as a person at the rig would use it, and prints
what it saw as JSON (tests/e2e/daemon_page.rs asserts on it).

Usage: page_check.py URL TOKEN RIG TEST_ID OUT_DIR
       page_check.py --sweep URL TOKEN RIG TEST_ID OUT_DIR

The daemon runs TEST_ID on RIG and needs TOKEN. The page is loaded, the
token typed into its form; the rig card must show the test running with
its progress and a plot fed from the event stream; the page's Abort button
aborts it; the record's report and plot are opened from the records list;
the page's emergency stop latches the rig and its reset clears it.
Screenshots go to OUT_DIR (01-token.png … 05-latched.png).

With --sweep, TEST_ID is an induction-machine slip sweep: the card must
plot its operating points (line current and input power against slip) as
they arrive, beside the live plot; the page's Abort button then aborts
it. Screenshots: 11-sweep.png, 12-sweep-aborted.png.

With --cut-feed, every request for a test's event feed is failed in the
browser (as a dropped connection or a proxy that closes long answers
would): the card must still show the test running, from its status, and
once aborted from the page, how it ended. Screenshot: 21-feed-cut.png. Chromium is
/usr/bin/chromium unless MOTORBENCH_CHROMIUM names another; without it the
script fails (exit 2) and says how to install it.
"""

import asyncio
import base64
import itertools
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading

from websockets.asyncio.client import connect

PATIENCE_S = 120.0
FLAGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--remote-debugging-port=0",
]


class Failure(Exception):
    pass


class Browser:
    """One Chromium process and one page, driven over a DevTools socket."""

    def __init__(self, out_dir):
        self.out_dir = out_dir
        self.ids = itertools.count(1)
        self.pending = {}
        self.requests = []
        self.console_errors = []
        self.session = None
        self.feeds_cut = 0

    async def start(self):
        exe = os.environ.get("MOTORBENCH_CHROMIUM", "/usr/bin/chromium")
        if not shutil.which(exe):
            print(f"{exe}: Chromium is not installed; tests/run.sh installs Debian's "
                  "package (apt-get install chromium)", file=sys.stderr)
            sys.exit(2)
        self.profile = tempfile.mkdtemp(prefix="motorbench-chromium-")
        self.proc = subprocess.Popen(
            [exe, *FLAGS, f"--user-data-dir={self.profile}", "about:blank"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        url = await asyncio.wait_for(asyncio.to_thread(self._devtools_url), PATIENCE_S)
        self.ws = await connect(url, max_size=None)
        self.reader = asyncio.create_task(self._read())
        target = await self.send("Target.createTarget", {"url": "about:blank"}, browser=True)
        attached = await self.send(
            "Target.attachToTarget", {"targetId": target["targetId"], "flatten": True}, browser=True)
        self.session = attached["sessionId"]
        for domain in ("Page", "Runtime", "Network"):
            await self.send(f"{domain}.enable")
        await self.send("Emulation.setDeviceMetricsOverride",
                        {"width": 1280, "height": 1000, "deviceScaleFactor": 1, "mobile": False})

    def _devtools_url(self):
        for line in self.proc.stderr:
            if line.startswith("DevTools listening on "):
                # Keep draining stderr so Chromium never blocks on it.
                threading.Thread(target=self._drain, daemon=True).start()
                return line.split(" on ", 1)[1].strip()
        raise Failure("Chromium ended without a DevTools address")

    def _drain(self):
        for _ in self.proc.stderr:
            pass

    async def _read(self):
        async for text in self.ws:
            msg = json.loads(text)
            if "id" in msg:
                fut = self.pending.pop(msg["id"], None)
                if fut and not fut.done():
                    fut.set_result(msg)
                continue
            method, params = msg.get("method"), msg.get("params", {})
            if method == "Network.requestWillBeSent":
                self.requests.append(params["request"]["url"])
            elif method == "Fetch.requestPaused":
                # Only the event feeds are paused (see cut_event_feeds).
                self.feeds_cut += 1
                asyncio.create_task(self.send("Fetch.failRequest", {
                    "requestId": params["requestId"], "errorReason": "ConnectionClosed"}))
            elif method == "Runtime.exceptionThrown":
                self.console_errors.append(params["exceptionDetails"].get("text", "exception"))
            elif method == "Runtime.consoleAPICalled" and params.get("type") == "error":
                self.console_errors.append(" ".join(str(a.get("value", "")) for a in params["args"]))

    async def send(self, method, params=None, browser=False):
        i = next(self.ids)
        msg = {"id": i, "method": method, "params": params or {}}
        if not browser:
            msg["sessionId"] = self.session
        fut = asyncio.get_running_loop().create_future()
        self.pending[i] = fut
        await self.ws.send(json.dumps(msg))
        reply = await asyncio.wait_for(fut, PATIENCE_S)
        if "error" in reply:
            raise Failure(f"{method}: {reply['error']}")
        return reply.get("result", {})

    async def cut_event_feeds(self):
        """Fail every request for a test's event feed from now on."""
        await self.send("Fetch.enable", {"patterns": [{"urlPattern": "*/v1/tests/*/events"}]})

    async def js(self, expression):
        r = await self.send("Runtime.evaluate", {
            "expression": expression, "returnByValue": True, "awaitPromise": True})
        if "exceptionDetails" in r:
            raise Failure(f"{expression}: {r['exceptionDetails']}")
        return r["result"].get("value")

    async def wait(self, what, expression):
        """Poll `expression` until it is truthy; its value. Bounded."""
        loop = asyncio.get_running_loop()
        end = loop.time() + PATIENCE_S
        value = None
        while loop.time() < end:
            try:
                value = await self.js(expression)
            except Failure as e:
                # The page is still loading (an element not there yet).
                value = str(e)
            else:
                if value:
                    return value
            await asyncio.sleep(0.1)
        await self.screenshot("timeout")
        raise Failure(f"waited too long for {what}; last {value!r}; page text: "
                      f"{await self.js('document.body.innerText')!r}")

    async def screenshot(self, name):
        shot = await self.send("Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True})
        path = os.path.join(self.out_dir, f"{name}.png")
        with open(path, "wb") as f:
            f.write(base64.b64decode(shot["data"]))
        return path

    async def close(self):
        try:
            await self.send("Browser.close", browser=True)
        except Exception:
            pass
        self.reader.cancel()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        shutil.rmtree(self.profile, ignore_errors=True)


def card(rig, expression):
    """A JavaScript expression over the rig's card `c` (null while absent)."""
    return (f"(() => {{ const c = document.querySelector('[data-rig=\"{rig}\"]'); "
            f"return c ? ({expression}) : null; }})()")


CARD_TEXT = ("({state: c.dataset.state, badge: c.querySelector('.state').textContent, "
             "test: c.querySelector('.test').textContent, segment: c.querySelector('.segment').textContent, "
             "time: c.querySelector('.time').textContent, eta: c.querySelector('.eta').textContent, "
             "values: c.querySelector('.values').textContent, points: Number(c.dataset.points || 0), "
             "canvas: !!c.querySelector('.plot canvas'), trip: c.querySelector('.trip').textContent, "
             "message: c.querySelector('.message').textContent})")


SWEEP_TEXT = ("({points: Number(c.dataset.sweepPoints || 0), "
              "canvas: !!c.querySelector('.sweep canvas'), visible: !c.querySelector('.sweep').hidden, "
              "legend: Array.from(c.querySelectorAll('.sweep .u-legend .u-label')).map(e => e.textContent), "
              "title: (c.querySelector('.sweep .u-title') || {}).textContent || '', "
              "time_points: Number(c.dataset.points || 0), segment: c.querySelector('.segment').textContent})")


async def open_with_token(b, url, token, seen, shot=None):
    """Load the page and type the token into its form, once (a screenshot
    `shot` of the form first, when named)."""
    await b.send("Page.navigate", {"url": url})
    await b.wait("the token form", "!document.getElementById('token-form').hidden")
    seen["token_form"] = await b.js("document.getElementById('token-form').innerText")
    seen["shots"] = [await b.screenshot(shot)] if shot else []
    await b.js("document.getElementById('token-input').focus()")
    await b.send("Input.insertText", {"text": token})
    await b.js("document.querySelector('#token-form button[type=submit]').click()")


async def abort_from_page(b, rig, what):
    """Click the card's Abort button; `what` (an expression over the card)
    once the rig is idle and the test shown aborted."""
    await b.js(card(rig, "c.querySelector('button.abort').click()"))
    return await b.wait("the test aborted", card(
        rig, f"c.dataset.state === 'idle' && c.querySelector('.eta').textContent.startsWith('aborted') "
             f"&& {what}"))


async def run_sweep(url, token, rig, test_id, out_dir):
    b = Browser(out_dir)
    await b.start()
    seen = {}
    try:
        await open_with_token(b, url, token, seen)
        # The sweep's operating points, plotted as they arrive.
        first = await b.wait("a sweep plot with 3 operating points", card(
            rig, f"c.dataset.state === 'running' && c.querySelector('.test').textContent.includes('{test_id}') "
                 f"&& Number(c.dataset.sweepPoints || 0) >= 3 && {SWEEP_TEXT}"))
        seen["sweep_first"] = first
        seen["sweep"] = await b.wait("2 more operating points", card(
            rig, f"c.dataset.state === 'running' && Number(c.dataset.sweepPoints || 0) >= {first['points'] + 2} "
                 f"&& {SWEEP_TEXT}"))
        await b.js(card(rig, "c.scrollIntoView()"))
        seen["shots"].append(await b.screenshot("11-sweep"))
        seen["aborted"] = await abort_from_page(b, rig, f"Object.assign({CARD_TEXT}, {{sweep: {SWEEP_TEXT}}})")
        seen["shots"].append(await b.screenshot("12-sweep-aborted"))
        seen["requests"] = b.requests
        seen["console_errors"] = b.console_errors
    finally:
        await b.close()
    return seen


async def run(url, token, rig, test_id, out_dir):
    b = Browser(out_dir)
    await b.start()
    seen = {}
    try:
        await open_with_token(b, url, token, seen, "01-token")

        # The running test: state, progress and a plot fed by the event
        # stream, from its second step on (the plot then shows a step response).
        first = await b.wait("the test's second step with 20 plotted points", card(
            rig, f"c.dataset.state === 'running' && Number(c.dataset.points || 0) >= 20 && "
                 f"Number((c.querySelector('.segment').textContent.match(/^segment (\\d+)\\//) || [])[1]) >= 2 && "
                 f"c.querySelector('.test').textContent.includes('{test_id}') && {CARD_TEXT}"))
        seen["running"] = await b.wait("10 more points", card(
            rig, f"c.dataset.state === 'running' && Number(c.dataset.points) >= {first['points'] + 10} "
                 f"&& {CARD_TEXT}"))
        seen["shots"].append(await b.screenshot("02-running"))

        # Abort from the page.
        seen["aborted"] = await abort_from_page(b, rig, CARD_TEXT)
        seen["shots"].append(await b.screenshot("03-aborted"))

        # The record: report and plot from the records list.
        row = f"document.querySelector('tr[data-record=\"{test_id}\"]')"
        seen["record_row"] = await b.wait("the record listed as aborted with a report",
                                          f"{row} && {row}.querySelector('button.show') && "
                                          f"{row}.innerText.includes('aborted') && {row}.innerText")
        await b.js(f"{row}.querySelector('button.show').click()")
        seen["record_view"] = await b.wait("the record's report and plot", (
            "(() => { const v = document.getElementById('record-view'); const img = v.querySelector('img'); "
            "return img && img.complete && img.naturalWidth > 0 && v.querySelector('table.report tbody tr') "
            "? {text: v.innerText, plot_width: img.naturalWidth, plot_height: img.naturalHeight} : null; })()"))
        await b.js("document.getElementById('record-view').scrollIntoView()")
        seen["shots"].append(await b.screenshot("04-record"))

        # Emergency stop from the page latches the rig; reset clears it.
        await b.js(card(rig, "c.querySelector('button.estop').click()"))
        seen["latched"] = await b.wait("the rig latched", card(
            rig, f"c.dataset.state === 'tripped' && !c.querySelector('button.reset').disabled && {CARD_TEXT}"))
        seen["shots"].append(await b.screenshot("05-latched"))
        await b.js(card(rig, "c.querySelector('button.reset').click()"))
        seen["reset"] = await b.wait("the rig idle again", card(
            rig, f"c.dataset.state === 'idle' && c.querySelector('.trip').textContent === '' && {CARD_TEXT}"))
        seen["requests"] = b.requests
        seen["console_errors"] = b.console_errors
    finally:
        await b.close()
    return seen


async def run_cut_feed(url, token, rig, test_id, out_dir):
    b = Browser(out_dir)
    await b.start()
    seen = {}
    try:
        await b.cut_event_feeds()
        await open_with_token(b, url, token, seen)
        seen["running"] = await b.wait("the test shown running without its feed", card(
            rig, f"c.dataset.state === 'running' && c.querySelector('.test').textContent.includes('{test_id}') "
                 f"&& c.querySelector('.test').textContent.includes('running') && {CARD_TEXT}"))
        seen["aborted"] = await abort_from_page(b, rig, CARD_TEXT)
        seen["shots"].append(await b.screenshot("21-feed-cut"))
        seen["feeds_cut"] = b.feeds_cut
        seen["requests"] = b.requests
        seen["console_errors"] = b.console_errors
    finally:
        await b.close()
    return seen


def main():
    args = sys.argv[1:]
    modes = {"--sweep": run_sweep, "--cut-feed": run_cut_feed}
    check = run
    if args and args[0] in modes:
        check = modes[args[0]]
        args = args[1:]
    url, token, rig, test_id, out_dir = args[:5]
    os.makedirs(out_dir, exist_ok=True)
    try:
        seen = asyncio.run(check(url, token, rig, test_id, out_dir))
    except Failure as e:
        print(e, file=sys.stderr)
        sys.exit(1)
    json.dump(seen, sys.stdout)


if __name__ == "__main__":
    main()
