"""The peer's DDS participant: Cyclone DDS on a domain id, confined to the loopback interface with
unicast discovery when asked (a test on one machine: no multicast leaves the host)."""

import os
import tempfile

LOOPBACK_XML = """<CycloneDDS><Domain Id="any"><General>
<Interfaces><NetworkInterface name="lo"/></Interfaces><AllowMulticast>false</AllowMulticast>
</General><Discovery><Peers><Peer address="127.0.0.1"/></Peers>
<ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>30</MaxAutoParticipantIndex>
</Discovery></Domain></CycloneDDS>"""


def participant(domain, loopback):
    """A DomainParticipant on `domain`; with `loopback`, Cyclone uses only 127.0.0.1 and finds
    peers by unicast to the well-known ports of participant indices 0..30 there (RustDDS answers
    on those)."""
    if loopback:
        path = os.path.join(tempfile.gettempdir(), f"handeye-ros2-peer-cyclone-{os.getpid()}.xml")
        with open(path, "w") as f:
            f.write(LOOPBACK_XML)
        os.environ["CYCLONEDDS_URI"] = "file://" + path
    from cyclonedds.domain import DomainParticipant

    return DomainParticipant(domain)


def qos_static(depth=1):
    """Latched: a writer's last message reaches late joiners. A reader of several writers keeps
    `depth` messages (tf2's /tf_static listener keeps 100), else one writer's hides another's."""
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    return Qos(
        Policy.Reliability.Reliable(duration(milliseconds=100)),
        Policy.Durability.TransientLocal,
        Policy.History.KeepLast(depth),
    )


def qos_reliable(depth=10):
    from cyclonedds.core import Policy, Qos
    from cyclonedds.util import duration

    return Qos(Policy.Reliability.Reliable(duration(milliseconds=100)), Policy.History.KeepLast(depth))


def qos_sensor(depth=5):
    from cyclonedds.core import Policy, Qos

    return Qos(Policy.Reliability.BestEffort, Policy.History.KeepLast(depth))
