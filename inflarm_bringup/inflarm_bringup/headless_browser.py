"""Headless Chromium driven over the DevTools protocol: load a page, wait, click, screenshot.

A small client for tests and for making screenshots of the live view (``inflarm_bringup.
live_view``): Chromium is started with ``--remote-debugging-port=0`` on a fresh profile, the
port it picked is read from its ``DevToolsActivePort`` file, and one page is driven over a
websocket (the ``websockets`` package, which viser depends on). Stdlib + websockets only.

    with HeadlessChromium() as browser:
        browser.navigate('http://127.0.0.1:8080')
        png = browser.screenshot()

`find_chromium` returns the browser's path or None; on Debian it is ``apt-get install chromium``.
"""

from __future__ import annotations

import base64
import itertools
import json
import os
import pathlib
import shutil
import subprocess
import tempfile
import time
import urllib.request

#: Where to get the browser, for messages.
INSTALL_HINT = 'apt-get install chromium (Debian), or set INFLARM_CHROMIUM to a Chromium binary'

#: Flags that work on a headless machine without a GPU or a network; WebGL runs on SwiftShader
#: (software), which Chromium only allows with --enable-unsafe-swiftshader since version 137.
CHROMIUM_FLAGS = (
    '--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
    '--enable-unsafe-swiftshader', '--disable-quic', '--no-first-run',
    '--disable-background-networking', '--disable-component-update', '--disable-sync',
    '--disable-dev-shm-usage', '--hide-scrollbars', '--mute-audio',
)


class BrowserError(RuntimeError):
    """Chromium did not start, or a DevTools command failed or timed out."""


def find_chromium() -> str | None:
    """The Chromium binary: ``$INFLARM_CHROMIUM``, else chromium or google-chrome on PATH."""
    override = os.environ.get('INFLARM_CHROMIUM')
    if override:
        return override if os.access(override, os.X_OK) else None
    for name in ('chromium', 'chromium-browser', 'google-chrome', 'google-chrome-stable'):
        path = shutil.which(name)
        if path:
            return path
    return None


class HeadlessChromium:
    """One headless Chromium process and one page of it, driven over the DevTools protocol.

    Parameters
    ----------
    width, height : int
        Window size [px].
    timeout_s : float
        Start-up and default command timeout [s].
    """

    def __init__(self, width: int = 1280, height: int = 800, timeout_s: float = 30.0,
                 binary: str | None = None) -> None:
        from websockets.sync.client import connect

        self.binary = binary or find_chromium()
        if self.binary is None:
            raise BrowserError(f'no Chromium found: {INSTALL_HINT}')
        self.timeout_s = timeout_s
        # Every URL the page asked for (Network.requestWillBeSent): a page that works offline
        # asks only its own server and data:/blob: URLs.
        self.requests: list[str] = []
        self.failed_requests: list[str] = []
        self.console: list[str] = []
        self._ids = itertools.count(1)
        self._profile = tempfile.mkdtemp(prefix='inflarm-chromium-')
        flags = [*CHROMIUM_FLAGS, f'--user-data-dir={self._profile}',
                 f'--window-size={width},{height}', '--remote-debugging-port=0',
                 '--remote-debugging-address=127.0.0.1']
        self._process = subprocess.Popen(
            [self.binary, *flags, 'about:blank'], stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            port = self._read_port()
            page = self._page_target(port)
            self._socket = connect(page['webSocketDebuggerUrl'], max_size=None, ping_interval=None,
                                   open_timeout=timeout_s)
            self.command('Page.enable')
            self.command('Network.enable')
            self.command('Runtime.enable')
            self.command('Emulation.setDeviceMetricsOverride', width=width, height=height,
                         deviceScaleFactor=1, mobile=False)
        except BaseException:
            self.close()
            raise

    def _read_port(self) -> int:
        active = pathlib.Path(self._profile) / 'DevToolsActivePort'
        deadline = time.monotonic() + self.timeout_s
        while time.monotonic() < deadline:
            if self._process.poll() is not None:
                error = self._process.stderr.read().decode(errors='replace')[-2000:]
                raise BrowserError(f'{self.binary} exited with code {self._process.returncode}:'
                                   f'\n{error}')
            if active.exists():
                lines = active.read_text().split()
                if lines:
                    return int(lines[0])
            time.sleep(0.05)
        raise BrowserError(f'{self.binary} opened no DevTools port within {self.timeout_s} s')

    def _page_target(self, port: int) -> dict:
        deadline = time.monotonic() + self.timeout_s
        while True:
            with urllib.request.urlopen(f'http://127.0.0.1:{port}/json/list', timeout=5) as reply:
                pages = [t for t in json.load(reply) if t.get('type') == 'page']
            if pages:
                return pages[0]
            if time.monotonic() > deadline:
                raise BrowserError('Chromium has no page target')
            time.sleep(0.05)

    # --- the protocol -------------------------------------------------------------------------

    def command(self, method: str, timeout_s: float | None = None, **params) -> dict:
        """Send one DevTools command and return its result; events seen meanwhile are noted."""
        command_id = next(self._ids)
        self._socket.send(json.dumps({'id': command_id, 'method': method, 'params': params}))
        deadline = time.monotonic() + (timeout_s or self.timeout_s)
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise BrowserError(f'{method}: no answer within {timeout_s or self.timeout_s} s')
            try:
                message = json.loads(self._socket.recv(timeout=remaining))
            except TimeoutError:
                continue
            if message.get('id') == command_id:
                if 'error' in message:
                    raise BrowserError(f"{method}: {message['error']}")
                return message.get('result', {})
            self._note_event(message)

    def _note_event(self, message: dict) -> None:
        method, params = message.get('method'), message.get('params', {})
        if method == 'Network.requestWillBeSent':
            self.requests.append(params['request']['url'])
        elif method == 'Network.loadingFailed':
            self.failed_requests.append(f"{params.get('errorText')} ({params.get('requestId')})")
        elif method == 'Runtime.consoleAPICalled':
            text = ' '.join(str(a.get('value', a.get('description', '')))
                            for a in params.get('args', []))
            self.console.append(f"{params.get('type')}: {text}")

    def navigate(self, url: str) -> None:
        """Load ``url`` and wait for its load event."""
        self.command('Page.navigate', url=url)
        self.wait_for('document.readyState === "complete"')

    def evaluate(self, expression: str):
        """The value of a JavaScript expression in the page (awaited when it is a promise)."""
        result = self.command('Runtime.evaluate', expression=expression, returnByValue=True,
                              awaitPromise=True)
        if 'exceptionDetails' in result:
            raise BrowserError(f'{expression!r}: {result["exceptionDetails"].get("text")} '
                               f'{result["exceptionDetails"].get("exception", {})}')
        return result.get('result', {}).get('value')

    def wait_for(self, expression: str, timeout_s: float | None = None) -> None:
        """Poll a JavaScript expression until it is truthy (bounded)."""
        limit = timeout_s or self.timeout_s
        deadline = time.monotonic() + limit
        while not self.evaluate(expression):
            if time.monotonic() > deadline:
                raise BrowserError(f'{expression!r} still false after {limit} s')
            time.sleep(0.1)

    def click(self, x: float, y: float) -> None:
        """A left mouse click at page coordinates ``(x, y)`` [CSS px]."""
        for kind in ('mousePressed', 'mouseReleased'):
            self.command('Input.dispatchMouseEvent', type=kind, x=x, y=y, button='left',
                         clickCount=1)

    def click_button(self, label: str) -> None:
        """Click the visible ``<button>`` whose text is ``label`` (as a user would, by mouse)."""
        box = self.evaluate(
            '(() => { const b = [...document.querySelectorAll("button")].find('
            f'e => e.innerText.trim() === {json.dumps(label)} && e.offsetParent !== null);'
            ' if (!b) return null; b.scrollIntoView({block: "center"});'
            ' const r = b.getBoundingClientRect();'
            ' return [r.left + r.width / 2, r.top + r.height / 2, b.disabled]; })()')
        if box is None:
            raise BrowserError(f'no visible button {label!r} on the page')
        if box[2]:
            raise BrowserError(f'button {label!r} is disabled')
        self.click(box[0], box[1])

    def screenshot(self) -> bytes:
        """The page as a PNG."""
        return base64.b64decode(self.command('Page.captureScreenshot', format='png')['data'])

    # --- the process --------------------------------------------------------------------------

    def close(self) -> None:
        """End the page's connection and the browser, and remove the profile."""
        socket = getattr(self, '_socket', None)
        if socket is not None:
            socket.close()
        if self._process.poll() is None:
            self._process.terminate()
            try:
                self._process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self._process.kill()
                self._process.wait()
        self._process.stderr.close()
        shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> HeadlessChromium:
        return self

    def __exit__(self, *exc_info) -> None:
        self.close()
