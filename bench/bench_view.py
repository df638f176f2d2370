"""Benchmark of the Foxglove live view: CPU the node's publishing thread pays for it.

In one process, no ROS node: a simulation (2D default and 3D default fruit) squeezes
at 5 N; every ``1 / publish_rate`` of sim time its messages are built
(``build_messages``, every topic: what the node builds while a Foxglove client
watches) and handed to a ``FoxgloveView`` on a free port, with one client (a thread
of this process) subscribed to what the shipped layout shows (the scene and the fruit
state) or to every channel. Figures: CPU time of the publishing
thread (``time.thread_time``) per batch for the physics step, the message build and
the view (serialising the ROS messages to CDR, the scene), and what that is per
simulated second at the node's default 100 Hz (a batch every step where a step is
longer than 10 ms).

Run: ``nice python bench/bench_view.py [--batches 200]``. Prints figures only.
"""
from __future__ import annotations

import argparse
import asyncio
import json
import threading
import time

import websockets

from gripper_sim.configuration import load_config
from gripper_sim.convert import messages
from gripper_sim.view.foxglove import FoxgloveView, node_topics
from gripper_sim.view.scene import PressureLegend
from gripper_sim.workflows.factory import make_simulation

PUBLISH_RATE = 100.0   # Hz of sim time, the node's default


def subscribe(url: str, topics: set[str] | None, stop: threading.Event,
              ready: threading.Event) -> None:
    """A client subscribed to ``topics`` (None = every channel), reading until ``stop``."""
    async def run() -> None:
        async with websockets.connect(url, subprotocols=['foxglove.sdk.v1'], proxy=None,
                                      max_size=None) as socket:
            channels: list[dict] = []
            while len(channels) < 8:
                message = await socket.recv()
                if isinstance(message, str) and json.loads(message)['op'] == 'advertise':
                    channels += json.loads(message)['channels']
            chosen = [c for c in channels if topics is None or c['topic'] in topics]
            await socket.send(json.dumps({'op': 'subscribe', 'subscriptions': [
                {'id': k, 'channelId': c['id']} for k, c in enumerate(chosen)]}))
            ready.set()
            while not stop.is_set():
                try:
                    await asyncio.wait_for(socket.recv(), 0.2)
                except asyncio.TimeoutError:
                    pass
    asyncio.run(run())


def measure(overrides: list[str], batches: int, watched: set[str] | None
            ) -> dict[str, float]:
    """CPU per batch (s) of the steps, the message build and the view, with a client
    subscribed to ``watched`` topics (None = all)."""
    config = load_config(overrides=overrides)
    sim = make_simulation(config)
    context = messages.MessageContext.from_config(config, initial=sim.last)
    topics = node_topics('gripper_sim', '/')
    names = {suffix: name for suffix, (name, _) in topics.items()}
    view = FoxgloveView({name: kind for name, kind in topics.values()},
                        legend=PressureLegend.beside(context), port=0)
    stop, ready = threading.Event(), threading.Event()
    client = threading.Thread(target=subscribe, args=(view.url, watched, stop, ready))
    client.start()
    ready.wait(60)
    deadline = time.monotonic() + 60.0   # until the server has taken the subscriptions
    while not view.channels['/gripper_sim/fruit/state'].has_sinks():
        assert time.monotonic() < deadline, 'the client did not subscribe'
        time.sleep(0.01)
    every = max(1, round(1.0 / (PUBLISH_RATE * sim.dt)))
    sim.command_force(5.0)
    cpu = {'step': 0.0, 'build': 0.0, 'view': 0.0}
    for _ in range(batches):
        t0 = time.thread_time()
        for _ in range(every):
            result = sim.step()
            context.observe(result)
        t1 = time.thread_time()
        batch = messages.build_messages(result, context.snapshot())
        t2 = time.thread_time()
        view.log_messages({names[s]: m for s, m in batch.items()}, int(result.time * 1e9))
        t3 = time.thread_time()
        cpu['step'] += t1 - t0
        cpu['build'] += t2 - t1
        cpu['view'] += t3 - t2
    stop.set()
    client.join()
    view.close()
    points = len(batch['markers'].markers[0].points)
    return {'dt': sim.dt, 'every': every, 'points': points, 'scenes': view.scenes,
            **{k: v / batches for k, v in cpu.items()}}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--batches', type=int, default=200)
    options = parser.parse_args()
    layout = {'/gripper_sim/scene', '/gripper_sim/fruit/state'}
    cases = [(label, overrides, watched, topics)
             for label, overrides in (('2D default', []), ('3D default', ['dimension=3']))
             for watched, topics in (('the layout (scene, fruit state)', layout),
                                     ('every channel', None))]
    for label, overrides, watched, topics in cases:
        f = measure(overrides, options.batches, topics)
        print(f"{label}, client on {watched}: dt {f['dt']:g} s, {f['every']} steps a "
              f"batch, fruit marker {f['points']} points, {f['scenes']} scenes sent")
        print(f"  CPU per batch: steps {1e3 * f['step']:.2f} ms, build messages "
              f"{1e3 * f['build']:.2f} ms, view {1e3 * f['view']:.2f} ms")
        # a batch every step where a step is longer than 1 / publish_rate (3D's 20 ms)
        per_second = 1.0 / (f['every'] * f['dt'])
        print(f"  per simulated second at {PUBLISH_RATE:g} Hz ({per_second:g} batches): "
              f"physics {f['step'] * per_second:.3f} s, build "
              f"{f['build'] * per_second:.3f} s, view {f['view'] * per_second:.3f} s CPU")

if __name__ == '__main__':
    main()
