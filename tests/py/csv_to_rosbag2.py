"""Writes a volcal campaign CSV as a rosbag2 bag with an independent writer (Python `rosbags`).

The bag holds what the issue calls a complete campaign and nothing of ours: the latched
`/interferometer/info` (`volcal_msgs/msg/InterferometerInfo`) and one
`/campaign/pairs` message (`volcal_msgs/msg/SyncedPair`) per CSV row, MCAP storage, rosbag2
metadata version 8 or 9. The message types come from the `.msg` files in `msgs/`, registered
with rosbags' own parser; `std_msgs/Header` and `builtin_interfaces/Time` from its ROS 2
(Jazzy) type store. volcal's code is not used.

usage: csv_to_rosbag2.py CAMPAIGN.csv OUT_BAG_DIR MSG_DIR VERSION [MODE]

MODE `pairs` (the default) writes the campaign; `info-only` only `/interferometer/info`;
`foreign` only a `/chatter` topic of `std_msgs/msg/String` (for the errors on such bags).
"""

import csv
import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

START_NS = 1_700_000_000_000_000_000
CO2_PPM = 450.0  # what the CSV format assumes (DESIGN.md section 4)


def main(src: str, out: str, msg_dir: str, version: str, mode: str = 'pairs') -> None:
    store = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for p in sorted(Path(msg_dir).glob('*.msg')):
        types.update(get_types_from_msg(p.read_text(), f'volcal_msgs/msg/{p.stem}'))
    store.register(types)
    Time = store.types['builtin_interfaces/msg/Time']
    Header = store.types['std_msgs/msg/Header']
    Info = store.types['volcal_msgs/msg/InterferometerInfo']
    Pair = store.types['volcal_msgs/msg/SyncedPair']

    meta = {}
    rows = []
    with open(src, newline='') as f:
        lines = [l for l in f]
    for l in lines:
        if l.startswith('#'):
            if ':' in l:
                k, v = l[1:].split(':', 1)
                meta[k.strip()] = v.strip()
    body = [l for l in lines if not l.startswith('#') and l.strip()]
    rows = list(csv.DictReader(body))

    def stamp(ns: int):
        return Header(stamp=Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000), frame_id='')

    def num(r, k, default=0.0):
        v = r.get(k)
        return float(v) if v not in (None, '') else default

    with Writer(out, version=int(version), storage_plugin=StoragePlugin.MCAP) as w:
        if mode == 'foreign':
            String = store.types['std_msgs/msg/String']
            cs = w.add_connection('/chatter', String.__msgtype__, typestore=store)
            for i in range(3):
                w.write(cs, START_NS + i, store.serialize_cdr(String(data=f'hello {i}'), String.__msgtype__))
            print(f'wrote 3 messages on /chatter to {out}')
            return
        ci = w.add_connection('/interferometer/info', Info.__msgtype__, typestore=store)
        cp = w.add_connection('/campaign/pairs', Pair.__msgtype__, typestore=store)
        info = Info(
            header=stamp(START_NS),
            instrument='csv',
            wavelength_vac_m=float(meta.get('wavelength_vac_m', '6.3299121258e-7')),
            compensated=meta.get('readings', 'compensated') == 'compensated',
            assumed_index=float(meta.get('assumed_index', '1.0')),
            air_equation=meta.get('air_equation', 'ciddor'),
        )
        w.write(ci, START_NS, store.serialize_cdr(info, Info.__msgtype__))
        if mode == 'info-only':
            print(f'wrote /interferometer/info only to {out}')
            return
        has_air = 'air_temp_c' in rows[0]
        has_temp = 'machine_temp_c' in rows[0]
        has_vel = 'vx_mps' in rows[0]
        for i, r in enumerate(rows):
            t_ns = START_NS + round(num(r, 't_s') * 1e9)
            pair = Pair(
                header=stamp(t_ns),
                kind=0 if r['kind'] == 'beam' else 1,
                station=int(r['station']),
                line=int(r['beam']),
                point=i,
                t_s=num(r, 't_s'),
                l_m=num(r, 'l_m'),
                position_m=np.array([num(r, 'x_m'), num(r, 'y_m'), num(r, 'z_m')], dtype=np.float64),
                probe_offset_m=np.array([num(r, 'px_m'), num(r, 'py_m'), num(r, 'pz_m')], dtype=np.float64),
                velocity_mps=np.array([num(r, 'vx_mps'), num(r, 'vy_mps'), num(r, 'vz_mps')], dtype=np.float64),
                beam_broken=r.get('beam_broken', '0') == '1',
                # Velocities travel only with pairs interpolated on the fly.
                pairing=1 if has_vel else 0,
                clock_offset_s=0.0,
                pairing_gap_s=0.0,
                trigger_id=i,
                air_valid=has_air,
                air_temp_c=num(r, 'air_temp_c'),
                air_pressure_pa=num(r, 'air_pressure_pa'),
                air_rh_pct=num(r, 'air_rh_pct'),
                air_co2_ppm=CO2_PPM,
                machine_temp_valid=has_temp,
                machine_temp_c=num(r, 'machine_temp_c'),
            )
            w.write(cp, t_ns, store.serialize_cdr(pair, Pair.__msgtype__))
    print(f'wrote {len(rows)} pairs to {out} (rosbag2 metadata version {version}, MCAP, rosbags)')


if __name__ == '__main__':
    main(*sys.argv[1:])
