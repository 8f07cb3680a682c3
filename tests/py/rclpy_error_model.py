#!/usr/bin/env python3
"""An independent receiver of volcal's error model: an rclpy node (Fast DDS) that subscribes to
/error_model (volcal_msgs/msg/ErrorModel) with the latched QoS the solver publishes with
(reliable, transient-local, keep-last 1), waits up to --timeout seconds for one message and
prints one JSON object with what it received (every scalar field, the header stamp, the sizes of
the sequences, and the model_json string's length and SHA-256).

With --model FILE (the model file the solver wrote) it also checks that the message carries that
model: model_json parses to the same JSON value as the file, and the message's fields agree with
the file's (format, topology, gauge, function names and coefficients, squareness, covariance,
residual statistics, provenance). The result is in "model_file": {"match": bool, "mismatches": [...]}.

Python type support for volcal_msgs comes from the overlay .ci/build_rclpy_msgs.sh builds. Either
run with AMENT_PREFIX_PATH=OVERLAY:VENV PYTHONPATH=OVERLAY/lib/python3.11/site-packages
LD_LIBRARY_PATH=OVERLAY/lib:VENV/lib, or pass --overlay OVERLAY and the script sets them (it
re-executes itself once so that the dynamic loader sees LD_LIBRARY_PATH).

Exit code: 0 when a message arrived (and, with --model, matches), 1 on timeout, 2 on a mismatch.
"""
import argparse
import hashlib
import json
import os
import re
import sys
import time


def parse_args():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--topic', default='/error_model')
    ap.add_argument('--timeout', type=float, default=30.0, help='seconds to wait for a message')
    ap.add_argument('--model', help='model file written by the solver, to compare with')
    ap.add_argument('--overlay', help='volcal_msgs overlay prefix (from .ci/build_rclpy_msgs.sh)')
    ap.add_argument('--node-name', default='rclpy_error_model')
    return ap.parse_args()


def use_overlay(overlay):
    """Points the environment at the overlay and re-executes once (LD_LIBRARY_PATH is read by
    the dynamic loader at start-up only)."""
    overlay = os.path.abspath(overlay)
    venv = sys.prefix
    pyver = f'python{sys.version_info[0]}.{sys.version_info[1]}'
    want = {
        'AMENT_PREFIX_PATH': [overlay, venv],
        'PYTHONPATH': [os.path.join(overlay, 'lib', pyver, 'site-packages')],
        'LD_LIBRARY_PATH': [os.path.join(overlay, 'lib'), os.path.join(venv, 'lib')],
    }
    changed = False
    for var, paths in want.items():
        have = [p for p in os.environ.get(var, '').split(os.pathsep) if p]
        missing = [p for p in paths if p not in have]
        if missing:
            os.environ[var] = os.pathsep.join(missing + have)
            changed = True
    if changed and os.environ.get('VOLCAL_OVERLAY_REEXEC') != '1':
        os.environ['VOLCAL_OVERLAY_REEXEC'] = '1'
        os.execv(sys.executable, [sys.executable] + sys.argv)
    sys.path[:0] = want['PYTHONPATH']


def summarize(msg, received_after_s):
    model_json = msg.model_json
    return {
        'topic_type': 'volcal_msgs/msg/ErrorModel',
        'received_after_s': round(received_after_s, 3),
        'stamp': {'sec': msg.header.stamp.sec, 'nanosec': msg.header.stamp.nanosec},
        'stamp_ns': msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec,
        'frame_id': msg.header.frame_id,
        'format': msg.format,
        'topology': msg.topology,
        'travel_m': [float(v) for v in msg.travel_m],
        'gauge': msg.gauge,
        'n_functions': len(msg.functions),
        'function_names': [f.name for f in msg.functions],
        'n_coefficients': sum(len(f.coefficients) for f in msg.functions),
        'squareness_names': list(msg.squareness_names),
        'squareness_rad': [float(v) for v in msg.squareness_rad],
        'covariance_dim': msg.covariance_dim,
        'covariance_len': len(msg.covariance_upper),
        'n_obs': msg.n_obs,
        'residual_rms_m': msg.residual_rms_m,
        'chi2': msg.chi2,
        'dof': msg.dof,
        'variance_factor': msg.variance_factor,
        'n_identifiability': len(msg.identifiability),
        'n_warnings': len(msg.warnings),
        'input': msg.input,
        'input_sha256': msg.input_sha256,
        'machine': msg.machine,
        'machine_sha256': msg.machine_sha256,
        'software': msg.software,
        'model_json_len': len(model_json.encode('utf-8')),
        'model_json_sha256': hashlib.sha256(model_json.encode('utf-8')).hexdigest(),
    }


def compare_with_file(msg, path):
    """What differs between the message and the model file (empty: they agree)."""
    with open(path, encoding='utf-8') as f:
        text = f.read()
    file = json.loads(text)
    bad = []

    def check(what, got, want):
        if got != want:
            bad.append(f'{what}: message {got!r:.200} != file {want!r:.200}')

    # The solver writes the file pretty-printed and puts the same value compact in model_json
    # (serde_json::to_string_pretty and to_string: same number and string text, other
    # whitespace). The file with the whitespace between tokens removed must therefore be
    # byte for byte the message's model_json.
    compact = ''.join(re.findall(r'"(?:[^"\\]|\\.)*"|[^\s"]+', text))
    compact_sha = hashlib.sha256(compact.encode('utf-8')).hexdigest()
    check('sha256(model_json) vs sha256(file without whitespace)',
          hashlib.sha256(msg.model_json.encode('utf-8')).hexdigest(), compact_sha)
    check('model_json (parsed)', json.loads(msg.model_json), file)
    check('format', msg.format, file.get('format'))
    check('topology', msg.topology, file.get('topology'))
    travel = [v for r in file.get('travel', []) for v in r]
    check('travel_m', [float(v) for v in msg.travel_m], travel)
    funcs = file.get('functions', [])
    check('function names', [f.name for f in msg.functions], [e.get('name') for e in funcs])
    check('coefficients', [[float(c) for c in f.coefficients] for f in msg.functions],
          [e.get('coefficients') for e in funcs])
    check('representations', [json.loads(f.representation) for f in msg.functions],
          [e.get('representation') for e in funcs])
    cov = file.get('covariance', {})
    check('covariance_dim', msg.covariance_dim, cov.get('n'))
    check('covariance_upper', [float(v) for v in msg.covariance_upper], cov.get('upper'))
    res = file.get('residuals') or {}
    for field, key in [('n_obs', 'n_obs'), ('residual_rms_m', 'rms_m'), ('chi2', 'chi2'),
                       ('dof', 'dof'), ('variance_factor', 'variance_factor')]:
        check(field, getattr(msg, field), res.get(key, 0))
    prov = file.get('provenance', {})
    for field in ['input', 'input_sha256', 'machine', 'machine_sha256', 'software']:
        check(field, getattr(msg, field), prov.get(field))
    check('squareness', [[n, float(v)] for n, v in zip(msg.squareness_names, msg.squareness_rad)],
          [list(e) for e in file.get('squareness', [])])
    check('identifiability', list(msg.identifiability),
          (file.get('identifiability') or {}).get('statements', []))
    check('warnings', list(msg.warnings), file.get('warnings', []))
    return {
        'path': os.path.abspath(path),
        'file_sha256': hashlib.sha256(text.encode('utf-8')).hexdigest(),
        'file_compact_sha256': compact_sha,
        'match': not bad,
        'mismatches': bad,
    }


def main():
    args = parse_args()
    if args.overlay:
        use_overlay(args.overlay)
    try:
        import rclpy
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
        from volcal_msgs.msg import ErrorModel
    except ImportError as e:
        print(f'rclpy_error_model: cannot import rclpy or volcal_msgs ({e}); build the overlay '
              'with .ci/build_rclpy_msgs.sh and pass --overlay', file=sys.stderr)
        return 1

    rclpy.init()
    node = rclpy.create_node(args.node_name)
    qos = QoSProfile(reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     history=HistoryPolicy.KEEP_LAST, depth=1)
    got = []
    start = time.monotonic()
    started_wall_ns = time.time_ns()

    def on_msg(m):
        got.append((m, time.monotonic() - start, time.time_ns()))

    node.create_subscription(ErrorModel, args.topic, on_msg, qos)
    deadline = start + args.timeout
    while not got and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=min(0.1, max(0.0, deadline - time.monotonic())))
    publishers = node.count_publishers(args.topic)
    node.destroy_node()
    rclpy.try_shutdown()
    if not got:
        print(f'rclpy_error_model: no {args.topic} message within {args.timeout} s '
              f'({publishers} publisher(s) seen)', file=sys.stderr)
        return 1
    msg, after, received_wall_ns = got[0]
    out = summarize(msg, after)
    # Wall clock: a subscription created after the message's stamp (the solver stamps it when
    # it publishes) received it as a late joiner, from the publisher's transient-local history.
    out['subscribed_wall_ns'] = started_wall_ns
    out['received_wall_ns'] = received_wall_ns
    out['late_joiner'] = started_wall_ns > out['stamp_ns']
    code = 0
    if args.model:
        cmp = compare_with_file(msg, args.model)
        out['model_file'] = cmp
        code = 0 if cmp['match'] else 2
    print(json.dumps(out, sort_keys=True))
    sys.stdout.flush()
    return code


if __name__ == '__main__':
    sys.exit(main())
