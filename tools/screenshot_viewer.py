"""
Screenshot the Rerun web viewer showing a recording, headless (regenerates doc/rerun_viewer.png).

About 2 minutes on 2 cores: the viewer renders in software.

    .venv/bin/pip install websocket-client     # not a project dependency
    apt-get install chromium                   # Debian's
    .venv/bin/python tools/screenshot_viewer.py out/fold.rrd doc/rerun_viewer.png

Serves the file with ``rerun --web-viewer``, opens it in headless Chromium through the
DevTools protocol and saves the page once the viewer has had ``--wait`` seconds to load
(the WebAssembly viewer draws after the page's load event, so ``chromium --screenshot``
alone captures an empty page).
"""

import argparse
import base64
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time
import urllib.request

import websocket

CHROMIUM_FLAGS = ['--headless', '--no-sandbox', '--disable-gpu', '--use-angle=swiftshader',
                  '--enable-unsafe-swiftshader', '--disable-background-networking',
                  '--disable-component-update', '--no-first-run', '--disable-sync',
                  '--remote-allow-origins=*']


def _devtools_page(port, timeout=20.0):
    """Return the websocket url of Chromium's first page, once its DevTools endpoint answers."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            tabs = json.load(urllib.request.urlopen(f'http://127.0.0.1:{port}/json'))
            return next(t['webSocketDebuggerUrl'] for t in tabs if t['type'] == 'page')
        except (OSError, StopIteration):
            time.sleep(0.2)
    raise RuntimeError('chromium did not start')


def _command(ws, ident, method, **params):
    ws.send(json.dumps({'id': ident, 'method': method, 'params': params}))
    while True:
        reply = json.loads(ws.recv())
        if reply.get('id') == ident:
            return reply.get('result', {})


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('rrd')
    parser.add_argument('png')
    parser.add_argument('--wait', type=float, default=90.0, help='seconds to let it load')
    parser.add_argument('--size', default='1600,1000')
    args = parser.parse_args(argv)
    rerun = Path(sys.executable).with_name('rerun')
    # its own process group: .venv/bin/rerun is a wrapper that starts the real viewer as
    # a child, which killing the wrapper alone leaves running (at 100 % of a core)
    viewer = subprocess.Popen([str(rerun), '--web-viewer', '--bind', '127.0.0.1',
                               '--web-viewer-port', '9090', '--port', '9876', args.rrd],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True)
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        browser = subprocess.Popen(['chromium', *CHROMIUM_FLAGS, f'--user-data-dir={profile}',
                                    f'--window-size={args.size}', '--remote-debugging-port=9333',
                                    'about:blank'],
                                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        try:
            ws = websocket.create_connection(_devtools_page(9333), timeout=120)
            _command(ws, 1, 'Page.navigate',
                     url='http://127.0.0.1:9090?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A9876%2Fproxy')
            for waited in range(0, int(args.wait), 15):
                print(f'waiting for the viewer: {waited} / {args.wait:.0f} s', flush=True)
                time.sleep(15)
            shot = _command(ws, 2, 'Page.captureScreenshot', format='png')
            Path(args.png).write_bytes(base64.b64decode(shot['data']))
            print(f'wrote {args.png}')
        finally:
            browser.kill()
            browser.wait()      # before its profile folder is removed
            os.killpg(viewer.pid, signal.SIGTERM)


if __name__ == '__main__':
    main()
