#!/usr/bin/env python3
"""A live glove session from Python, as docs/live.md shows it: fetches the frames' schema from
the server (GET /api/v1/live/schema, a FileDescriptorSet: no protoc needed), opens
/api/v1/live, streams SAMPLES glove samples at 1 kHz (the hand at rest above a sphere, the wrist
from a "tracker"), checks every answer decodes as icms.live.Feedback with one value per DOF and
finger, ends the session and prints the `stored` event as JSON.

Usage: live_client.py HOST:PORT SAMPLES
"""

import asyncio
import json
import sys
import urllib.request


async def run(addr, samples):
    import websockets
    from google.protobuf import descriptor_pb2, message_factory

    with urllib.request.urlopen(f"http://{addr}/api/v1/live/schema") as r:
        fds = descriptor_pb2.FileDescriptorSet.FromString(r.read())
    classes = message_factory.GetMessages(fds.file)
    Sample, Feedback = classes["icms.live.Sample"], classes["icms.live.Feedback"]

    async with websockets.connect(f"ws://{addr}/api/v1/live") as ws:
        await ws.send(json.dumps({
            "type": "start",
            "name": "python",
            "object": {"shape": "sphere", "radius": 0.04, "mass": 0.3, "mu": 0.8},
        }))
        started = json.loads(await ws.recv())
        assert started["type"] == "started", started
        dofs, fingers = len(started["dofs"]), len(started["fingers"])
        for i in range(samples):
            s = Sample(t_ns=i * 1_000_000, q=[0.1] * dofs, tau=[0.0] * dofs)
            s.wrist.position.z = 0.3
            s.wrist.orientation.w = 1.0
            await ws.send(s.SerializeToString())
            reply = await ws.recv()
            if not isinstance(reply, bytes):
                raise SystemExit(f"sample {i}: expected feedback, got {reply}")
            fb = Feedback.FromString(reply)
            assert fb.t_ns == i * 1_000_000, (i, fb.t_ns)
            assert len(fb.motor_q) == dofs and len(fb.feedback_torque) == dofs, fb
            assert len(fb.fingers) == fingers, fb
        await ws.send(json.dumps({"type": "end"}))
        async for msg in ws:
            event = json.loads(msg)
            if event["type"] == "stored":
                print(json.dumps(event))
                return 0
            if event["type"] == "error":
                raise SystemExit(f"error: {event['message']}")
    raise SystemExit("the server closed without a stored event")


def main(argv):
    if len(argv) != 3:
        print(__doc__, file=sys.stderr)
        return 2
    return asyncio.run(run(argv[1], int(argv[2])))


if __name__ == "__main__":
    sys.exit(main(sys.argv))
