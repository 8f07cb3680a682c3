#!/usr/bin/env python3
"""CycloneDDS subscriber of /diagnosis (the solver node's diagnosis, transient-local).

Usage: cyclone_diagnosis.py DOMAIN TIMEOUT_S [all]

Joins DDS domain DOMAIN on the loopback interface only and reads the DDS topic `rt/diagnosis`
with the DDS type `volcal_msgs::msg::dds_::Diagnosis_` (ROS 2's names for the topic /diagnosis of
type volcal_msgs/msg/Diagnosis), declared here independently of volcal from the .msg files
(Diagnosis, DiagnosedEffect, EffectParameter, ResidualLocation, LineResidual), with a transient-local reader
so that a diagnosis published before this reader matched still arrives. Prints {"ready": true}
once the reader exists, then the first sample as one JSON line (every double also as its IEEE
754 bits, exact whatever the JSON parser), or {"received": 0} after TIMEOUT_S. With `all`
(a live campaign), every sample as it arrives, each with "received_unix_s" (this process's wall
clock at reception), until one that is not partial (the campaign's final diagnosis) or TIMEOUT_S.
"""
import json
import struct
import sys
import time
from dataclasses import dataclass

from cyclone_loopback import Header_  # noqa: E402  (sets the loopback-only configuration first)

from cyclonedds.core import Policy, Qos  # noqa: E402
from cyclonedds.domain import DomainParticipant  # noqa: E402
from cyclonedds.idl import IdlStruct  # noqa: E402
from cyclonedds.idl.types import float64, sequence, uint8, uint32, uint64  # noqa: E402
from cyclonedds.sub import DataReader  # noqa: E402
from cyclonedds.topic import Topic  # noqa: E402
from cyclonedds.util import duration  # noqa: E402


@dataclass
class EffectParameter_(IdlStruct, typename="volcal_msgs::msg::dds_::EffectParameter_"):
    name: str
    value: float64
    uncertainty: float64
    unit: str


@dataclass
class DiagnosedEffect_(IdlStruct, typename="volcal_msgs::msg::dds_::DiagnosedEffect_"):
    id: str
    parameters: sequence[EffectParameter_]
    delta_rms_m: float64
    log10_bayes_factor: float64
    p_value: float64
    statement: str
    alternatives: sequence[str]


@dataclass
class ResidualLocation_(IdlStruct, typename="volcal_msgs::msg::dds_::ResidualLocation_"):
    kind: str
    label: str
    excess_chi2: float64
    share: float64
    fraction: float64
    p_value: float64
    detail: str


@dataclass
class LineResidual_(IdlStruct, typename="volcal_msgs::msg::dds_::LineResidual_"):
    kind: str
    station: uint32
    line: uint32
    segment: uint32
    n_readings: uint32
    rms_before_m: float64
    rms_after_m: float64
    flagged_by: sequence[str]


@dataclass
class Diagnosis_(IdlStruct, typename="volcal_msgs::msg::dds_::Diagnosis_"):
    header: Header_
    format: str
    verdict: uint8
    model: str
    input: str
    input_sha256: str
    machine: str
    machine_sha256: str
    software: str
    n_readings: uint64
    rms_before_m: float64
    rms_after_m: float64
    noise_rms_m: float64
    chi2_per_dof_before: float64
    chi2_per_dof_after: float64
    effects: sequence[DiagnosedEffect_]
    locations: sequence[ResidualLocation_]
    remaining: sequence[ResidualLocation_]
    unexplained: str
    map_change_rms_m: float64
    map_change_max_m: float64
    statements: sequence[str]
    diagnosis_json: str
    partial: bool
    lines: sequence[LineResidual_]


def bits(x):
    return struct.unpack("<Q", struct.pack("<d", x))[0]


def plain(v):
    """A sample as JSON-ready data; every float also as `<name>_bits`."""
    if isinstance(v, list):
        return [plain(x) for x in v]
    if hasattr(v, "__dataclass_fields__"):
        out = {}
        for k in v.__dataclass_fields__:
            x = getattr(v, k)
            out[k] = plain(x)
            if isinstance(x, float):
                out[k + "_bits"] = bits(x)
        return out
    return v


def main():
    domain, timeout = int(sys.argv[1]), float(sys.argv[2])
    every = len(sys.argv) > 3 and sys.argv[3] == "all"
    dp = DomainParticipant(domain)
    topic = Topic(dp, "rt/diagnosis", Diagnosis_)
    qos = Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.TransientLocal,
        Policy.History.KeepLast(16 if every else 1),
    )
    reader = DataReader(dp, topic, qos=qos)
    print(json.dumps({"ready": True}), flush=True)
    end = time.time() + timeout
    received = 0
    while time.time() < end:
        for s in reader.take(N=16):
            received += 1
            print(json.dumps({"sample": plain(s), "received_unix_s": time.time()}), flush=True)
            if not every or not s.partial:
                return
        time.sleep(0.02)
    print(json.dumps({"received": received}), flush=True)


if __name__ == "__main__":
    main()
