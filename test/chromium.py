"""A small headless-Chromium driver for the HTML report tests (DevTools protocol over a
local websocket, with the ``websockets`` package).

``Browser`` starts Debian's ``/usr/bin/chromium`` headless with a fresh profile and no
network of its own (``--remote-debugging-port=0``: the port Chromium chose is read from
``DevToolsActivePort`` in the profile), opens one page, and records every console error,
uncaught exception and request that is not a ``file:``/``data:``/``about:`` URL.
"""
from __future__ import annotations

import base64
import itertools
import json
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Any

from websockets.sync.client import connect

CHROMIUM = '/usr/bin/chromium'
FLAGS = ('--headless', '--no-sandbox', '--disable-gpu', '--disable-background-networking',
         '--disable-component-update', '--disable-sync', '--no-first-run',
         '--remote-debugging-port=0', '--remote-debugging-address=127.0.0.1',
         '--window-size=1280,2400', '--hide-scrollbars')
LOCAL_SCHEMES = ('file:', 'data:', 'about:', 'blob:')


class Browser:
    """Headless Chromium with one page (a context manager)."""

    def __init__(self, timeout: float = 120.0):
        self.timeout = timeout
        self.profile = Path(tempfile.mkdtemp(prefix='chromium-profile-'))
        self.process = subprocess.Popen([CHROMIUM, *FLAGS, f'--user-data-dir={self.profile}',
                                         'about:blank'], stdout=subprocess.DEVNULL,
                                        stderr=subprocess.DEVNULL)
        self._ids = itertools.count(1)
        self.console_errors: list[str] = []
        self.remote_requests: list[str] = []
        self.events: list[dict] = []
        port_file = self.profile / 'DevToolsActivePort'
        deadline = time.monotonic() + timeout
        while not (port_file.is_file() and len(port_file.read_text().splitlines()) >= 2):
            if time.monotonic() > deadline or self.process.poll() is not None:
                self.close()
                raise RuntimeError('chromium did not open its DevTools port')
            time.sleep(0.05)
        port, path = port_file.read_text().splitlines()[:2]
        self.socket = connect(f'ws://127.0.0.1:{port}{path}', max_size=None,
                              open_timeout=timeout).__enter__()
        target = self.call('Target.createTarget', url='about:blank')['targetId']
        self.session = self.call('Target.attachToTarget', targetId=target,
                                 flatten=True)['sessionId']
        for domain in ('Page', 'Runtime', 'Log', 'Network'):
            self.call(f'{domain}.enable', session=True)

    def __enter__(self) -> Browser:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        sock = getattr(self, 'socket', None)
        if sock is not None:
            sock.close()
        if self.process.poll() is None:
            self.process.terminate()
            try:
                self.process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait()
        shutil.rmtree(self.profile, ignore_errors=True)

    def _note(self, event: dict) -> None:
        method, params = event.get('method'), event.get('params', {})
        self.events.append(event)
        if method == 'Runtime.exceptionThrown':
            details = params['exceptionDetails']
            self.console_errors.append(details.get('exception', {}).get(
                'description', details.get('text', 'exception')))
        elif method == 'Runtime.consoleAPICalled' and params.get('type') == 'error':
            self.console_errors.append(' '.join(str(a.get('value', a.get('description')))
                                                for a in params.get('args', [])))
        elif method == 'Log.entryAdded' and params['entry'].get('level') == 'error':
            self.console_errors.append(params['entry'].get('text', ''))
        elif method == 'Network.requestWillBeSent':
            url = params['request']['url']
            if not url.startswith(LOCAL_SCHEMES):
                self.remote_requests.append(url)

    def call(self, method: str, session: bool = False, **params: Any) -> dict:
        """Send one command and wait for its answer (events meanwhile are noted)."""
        message_id = next(self._ids)
        message: dict[str, Any] = {'id': message_id, 'method': method, 'params': params}
        if session:
            message['sessionId'] = self.session
        self.socket.send(json.dumps(message))
        deadline = time.monotonic() + self.timeout
        while True:
            reply = json.loads(self.socket.recv(timeout=max(0.1, deadline - time.monotonic())))
            if reply.get('id') == message_id:
                if 'error' in reply:
                    raise RuntimeError(f'{method}: {reply["error"]}')
                return reply.get('result', {})
            self._note(reply)

    def wait_for_event(self, method: str) -> dict:
        """The first event ``method`` (already seen, or the next one)."""
        for event in self.events:
            if event.get('method') == method:
                return event
        deadline = time.monotonic() + self.timeout
        while True:
            event = json.loads(self.socket.recv(timeout=max(0.1, deadline - time.monotonic())))
            self._note(event)
            if event.get('method') == method:
                return event

    def open(self, path: Path) -> None:
        """Load a local file and wait for its load event."""
        self.events.clear()
        self.call('Page.navigate', session=True, url=path.resolve().as_uri())
        self.wait_for_event('Page.loadEventFired')

    def evaluate(self, expression: str) -> Any:
        """The value of a JavaScript expression (promises awaited)."""
        result = self.call('Runtime.evaluate', session=True, expression=expression,
                           returnByValue=True, awaitPromise=True)
        if 'exceptionDetails' in result:
            raise RuntimeError(f'{expression}: {result["exceptionDetails"]}')
        return result['result'].get('value')

    def wait_until(self, expression: str) -> Any:
        """Evaluate ``expression`` until it is truthy; its value."""
        deadline = time.monotonic() + self.timeout
        while True:
            value = self.evaluate(expression)
            if value:
                return value
            if time.monotonic() > deadline:
                raise TimeoutError(f'never true: {expression}')
            time.sleep(0.1)

    def click(self, x: float, y: float) -> None:
        """A left click at page coordinates (CSS pixels of the viewport)."""
        for kind in ('mouseMoved', 'mousePressed', 'mouseReleased'):
            self.call('Input.dispatchMouseEvent', session=True, type=kind, x=x, y=y,
                      button='left' if kind != 'mouseMoved' else 'none', clickCount=1)

    def screenshot(self, path: Path, clip: dict | None = None) -> bytes:
        """A PNG of the page (or of ``clip``: x, y, width, height in page pixels)."""
        params: dict[str, Any] = {'format': 'png', 'captureBeyondViewport': True}
        if clip is not None:
            params['clip'] = {**clip, 'scale': 1}
        data = base64.b64decode(self.call('Page.captureScreenshot', session=True,
                                          **params)['data'])
        path.write_bytes(data)
        return data
