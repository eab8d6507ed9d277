"""A tiny Chrome DevTools Protocol client over ``--remote-debugging-pipe`` (no websocket, no dependency): enough to
load a page, evaluate JavaScript and click, for the tests of ``hpe view``'s interactive parts.

Chromium reads commands from fd 3 and writes replies and events to fd 4, each a JSON object ended by a NUL byte
(https://chromedevtools.github.io/devtools-protocol/).
"""

from __future__ import annotations

import json
import os
import subprocess
import time


class Browser:
    def __init__(self, path, profile, size=(1400, 900), flags=()):
        r_child, w_parent = os.pipe()  # commands: parent -> chromium fd 3
        r_parent, w_child = os.pipe()  # replies: chromium fd 4 -> parent
        args = [
            path,
            *flags,
            f"--user-data-dir={profile}",
            "--remote-debugging-pipe",
            f"--window-size={size[0]},{size[1]}",
        ]

        def fds():
            os.dup2(r_child, 3)
            os.dup2(w_child, 4)

        self.proc = subprocess.Popen(
            args, preexec_fn=fds, close_fds=False, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
        )  # the fds must survive as 3 and 4: closing the others would run after preexec_fn
        os.close(r_child)
        os.close(w_child)
        self.w, self.r = os.fdopen(w_parent, "wb", buffering=0), os.fdopen(r_parent, "rb", buffering=0)
        self.buf, self.next_id, self.events, self.session = b"", 0, [], None
        target = self.send("Target.createTarget", url="about:blank")["targetId"]
        self.session = self.send("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        self.send("Page.enable")
        self.send("Runtime.enable")

    def _read(self):
        while b"\0" not in self.buf:
            chunk = self.r.read(1 << 16)
            if not chunk:
                raise RuntimeError("chromium closed the pipe: " + self.proc.stderr.read().decode()[-500:])
            self.buf += chunk
        msg, self.buf = self.buf.split(b"\0", 1)
        return json.loads(msg)

    def send(self, method, browser_level=False, **params):
        self.next_id += 1
        msg = {"id": self.next_id, "method": method, "params": params}
        if self.session and not method.startswith("Target."):
            msg["sessionId"] = self.session
        self.w.write(json.dumps(msg).encode() + b"\0")
        while True:
            m = self._read()
            if m.get("id") == self.next_id:
                if "error" in m:
                    raise RuntimeError(f"{method}: {m['error']}")
                return m.get("result", {})
            self.events.append(m)

    def wait_event(self, method, timeout=60):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for k, e in enumerate(self.events):
                if e.get("method") == method:
                    return self.events.pop(k)
            self.events.append(self._read())
        raise TimeoutError(method)

    def goto(self, url):
        self.send("Page.navigate", url=url)
        self.wait_event("Page.loadEventFired")

    def eval(self, expression):
        r = self.send("Runtime.evaluate", expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in r:
            raise RuntimeError(r["exceptionDetails"])
        return r["result"].get("value")

    def wait_for(self, expression, timeout=20):
        """Poll ``expression`` until it is truthy (scripts the page loads come in asynchronously)."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            v = self.eval(expression)
            if v:
                return v
            time.sleep(0.05)
        raise TimeoutError(expression)

    def click(self, x, y):
        for kind in ("mousePressed", "mouseReleased"):
            self.send("Input.dispatchMouseEvent", type=kind, x=x, y=y, button="left", clickCount=1)

    def console(self):
        """Console messages and uncaught exceptions seen so far."""
        out = []
        for e in self.events:
            if e.get("method") == "Runtime.consoleAPICalled":
                out.append(" ".join(str(a.get("value")) for a in e["params"]["args"]))
            elif e.get("method") == "Runtime.exceptionThrown":
                out.append(e["params"]["exceptionDetails"].get("text", "exception"))
        return out

    def close(self):
        try:
            self.send("Browser.close")
        except Exception:  # noqa: BLE001 - it may close the pipe before replying
            pass
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self.w.close()
        self.r.close()
