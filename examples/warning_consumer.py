"""Subscribe to every robot's collision warnings and print one line per warning.

Shows a subscriber written from docs/contract.md alone (zenoh and msgpack, nothing of asnn):
the keys `<prefix>/*/warning` (and `<prefix>/*/response` with --responses), the msgpack
Response map, and its targets' optional fields (`id`, `ttc`) read as None where absent.

    python examples/warning_consumer.py --connect tcp/127.0.0.1:7447 [--responses]

A warning is also a response: with --responses each warning is printed twice, once per key.
A plain subscriber gets what is published after it starts; a robot's last warning from before
needs zenoh-ext's advanced subscriber (docs/contract.md, "Zenoh key expressions").
Ctrl-C (or SIGTERM) ends it.
"""
import argparse
import json
import signal
import sys
import threading
import time

import msgpack
import zenoh


def make_config(endpoints):
    """A client of the router(s) at `endpoints`, without multicast scouting (for a fleet,
    start from deploy/zenoh/client.json5 instead: zenoh.Config.from_file)."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps(endpoints))
    config.insert_json5("scouting/multicast/enabled", "false")
    return config


printing = threading.Lock()  # callbacks run on several Zenoh threads: one line at a time


def show(value):  # an optional field's value: None where the map leaves it out
    return "None" if value is None else f"{value:.2f}" if isinstance(value, float) else value


def on_sample(sample):
    kind = str(sample.key_expr).rsplit("/", 1)[-1]  # "warning" or "response"
    try:
        m = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
        targets = " ".join(
            f"[id={show(t.get('id'))} x={t['x']:.1f} y={t['y']:.1f} ttc={show(t.get('ttc'))}]"
            for t in m["targets"])
        line = (f"{kind} robot={m['robot']} seq={m['seq']} stamp={m['stamp']:.3f} "
                f"collision={m['collision']} targets={len(m['targets'])} {targets}")
    except Exception as exc:  # an invalid message is reported, never fatal
        print(f"invalid {kind} on {sample.key_expr}: {exc!r}", file=sys.stderr, flush=True)
        return
    with printing:
        print(line.rstrip(), flush=True)


def main():
    parser = argparse.ArgumentParser(prog="warning_consumer", description=__doc__.split("\n")[0])
    parser.add_argument("--connect", metavar="ENDPOINT", action="append",
                        help="router endpoint, repeatable (default: tcp/127.0.0.1:7447)")
    parser.add_argument("--prefix", default="asnn", help="key prefix (default: asnn)")
    parser.add_argument("--responses", action="store_true",
                        help="print every response too, not only the warnings")
    args = parser.parse_args()
    config = make_config(args.connect or ["tcp/127.0.0.1:7447"])

    signal.signal(signal.SIGTERM, signal.default_int_handler)  # docker stop: as Ctrl-C
    zenoh.init_log_from_env_or("error")
    with zenoh.open(config) as session:
        kinds = ["warning", "response"] if args.responses else ["warning"]
        subscribers = [session.declare_subscriber(f"{args.prefix}/*/{kind}", on_sample)
                       for kind in kinds]
        print(f"listening on {', '.join(f'{args.prefix}/*/{k}' for k in kinds)}; Ctrl-C to quit",
              file=sys.stderr, flush=True)
        try:
            while True:
                time.sleep(1)
        except KeyboardInterrupt:
            pass
        for subscriber in subscribers:
            subscriber.undeclare()


if __name__ == "__main__":
    main()
