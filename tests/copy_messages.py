"""A generated message stream shared by the writer's copy tests and the appender's tests."""

from vdps_hil.record import schemas as S

EPOCH = S.DEFAULT_SIM_EPOCH_NS


def copy_messages(seed: int, n: int):
    """(topic, t_ns, log_time, payload) on three serial topics, per-topic t_ns increasing,
    log times not monotonic across topics."""
    import random

    rng = random.Random(seed)
    last = {}
    out = []
    for k in range(n):
        topic = rng.choice(("/raw/serial/a", "/raw/serial/b", "/raw/serial/c"))
        t = last[topic] = last.get(topic, 0) + rng.randrange(1, 2_000_000)
        out.append((topic, t, EPOCH + t + rng.randrange(0, 5_000_000), rng.randbytes(rng.randrange(0, 60))))
    return out
