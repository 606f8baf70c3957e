"""ROS bags in: bags written with rosbags' own writers (ROS 2 MCAP and sqlite3, ROS 1)
imported as datasets, cut into trials, labelled, and refused in one line when bad."""

from __future__ import annotations

import sqlite3
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from slipkit.cli import main
from slipkit.data import load_dataset
from slipkit.data.importers import read_rosbag
from slipkit.errors import SourceFormatError

rosbags = pytest.importorskip("rosbags")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin  # noqa: E402
from rosbags.rosbag2 import Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

STORE = get_typestore(Stores.LATEST)
T = STORE.types
STORAGES = ("mcap", "sqlite3", "ros1")
T0 = 1_700_000_000 * 10**9  # a wall-clock epoch, as real bags have, in ns
MS = 1_000_000
WRENCH = tuple(f"wrench.{p}.{a}" for p in ("force", "torque") for a in "xyz")
CUSTOM = "slip_msgs/msg/Taxels"
CUSTOM_MSG = "float32[3] pressure\nuint16 count\n"

#: a message to write: (topic, receive time in ns, message)
Message = tuple[str, int, Any]


def bag_path(folder: Path, name: str, storage: str) -> Path:
    """Where a bag named ``name`` goes: ``<name>.bag`` for ROS 1, a folder for ROS 2."""
    return folder / (f"{name}.bag" if storage == "ros1" else name)


def write_bag(
    path: Path,
    storage: str,
    messages: Sequence[Message],
    *,
    store: Any = STORE,
    types: dict[str, str] | None = None,
) -> Path:
    """Write ``messages`` into a bag with rosbags' own writer; topic types from the
    messages (or ``types``)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    kinds = dict(types or {})
    for topic, _, msg in messages:
        kinds.setdefault(topic, msg.__msgtype__)
    if storage == "ros1":
        with Writer1(path) as w1:
            conns = {
                t: w1.add_connection(t, k, typestore=store) for t, k in kinds.items()
            }
            for topic, when, msg in messages:
                w1.write(conns[topic], when, store.serialize_ros1(msg, kinds[topic]))
        return path
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer2(path, version=9, storage_plugin=plugin) as w2:
        conns2 = {t: w2.add_connection(t, k, typestore=store) for t, k in kinds.items()}
        for topic, when, msg in messages:
            w2.write(conns2[topic], when, store.serialize_cdr(msg, kinds[topic]))
    return path


def electrodes(values: Sequence[float]) -> Any:
    """A std_msgs/Float32MultiArray holding ``values``."""
    layout = T["std_msgs/msg/MultiArrayLayout"](dim=[], data_offset=0)
    return T["std_msgs/msg/Float32MultiArray"](
        layout=layout, data=np.asarray(values, dtype=np.float32)
    )


def header(ns: int) -> Any:
    stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    return T["std_msgs/msg/Header"](stamp=stamp, frame_id="ft")


def wrench(ns: int, fz: float) -> Any:
    """A geometry_msgs/WrenchStamped stamped ``ns`` with force z ``fz``."""
    v3 = T["geometry_msgs/msg/Vector3"]
    body = T["geometry_msgs/msg/Wrench"](
        force=v3(x=1.0, y=-2.0, z=fz), torque=v3(x=0.0, y=0.0, z=0.25)
    )
    return T["geometry_msgs/msg/WrenchStamped"](header=header(ns), wrench=body)


def recording(start: int, n: int = 20, k: int = 0) -> list[Message]:
    """``n`` electrode frames at 100 Hz (receive time) and ``2 n`` wrenches at 200 Hz
    stamped 3 ms before they were recorded, from ``start`` ns."""
    msgs: list[Message] = []
    for i in range(n):
        msgs.append(
            ("/biotac/electrodes", start + i * 10 * MS, electrodes([k, i, 2.0 * i]))
        )
    for j in range(2 * n):
        stamp = start + j * 5 * MS
        msgs.append(("/ft", stamp + 3 * MS, wrench(stamp, 0.5 * j)))
    return sorted(msgs, key=lambda m: m[1])


def make_bags(
    folder: Path, storage: str, n_bags: int = 3, labels: str | None = None
) -> Path:
    """``n_bags`` bags bag0, bag1... of :func:`recording`, and ``labels.csv`` if given."""
    for k in range(n_bags):
        write_bag(
            bag_path(folder, f"bag{k}", storage),
            storage,
            recording(T0 + k * 10**11, k=k),
        )
    if labels is not None:
        (folder / "labels.csv").write_text(labels, encoding="utf-8")
    return folder


TOPICS = {"/biotac/electrodes": "electrodes", "/ft": "wrench"}
LABELS = "bag,slip_onset_s,object\nbag0,0.05,cube\nbag1,,ball\nbag2,0.1,cube\n"


# -- what a bag becomes ------------------------------------------------------------------
@pytest.mark.parametrize("storage", STORAGES)
def test_bags_import_with_trials_channels_rates(tmp_path: Path, storage: str) -> None:
    """Each storage: one trial per bag, channels by field, a rate per topic, labels."""
    ds = read_rosbag(
        make_bags(tmp_path / "bags", storage, labels=LABELS), topics=TOPICS
    )
    assert ["bag0", "bag1", "bag2"] == ds.trial_ids
    el, wr = ds.streams["electrodes"], ds.streams["wrench"]
    assert (("data_0", "data_1", "data_2"), 100.0) == (el.channels, el.rate_hz)
    assert (WRENCH, 200.0) == (wr.channels, wr.rate_hz)
    assert {"N", "N m"} == set(wr.units.values())
    assert ("object",) == ds.groups
    assert ["cube", "ball", "cube"] == ds.trials["object"].tolist()
    onset = ds.trials["slip_onset_s"].to_numpy()
    assert [0.05, True, 0.1] == [onset[0], bool(np.isnan(onset[1])), onset[2]]
    assert "s" == ds.labels["slip_onset_s"].unit
    assert (20, 40) == (
        len(ds["bag1"].streams["electrodes"]),
        len(ds["bag1"].streams["wrench"]),
    )


@pytest.mark.parametrize("storage", STORAGES)
def test_values_and_times_are_the_messages(tmp_path: Path, storage: str) -> None:
    """Channel values are the message fields; t is header.stamp (else the recording
    time) in s from the bag's first sample."""
    ds = read_rosbag(make_bags(tmp_path / "bags", storage, n_bags=2), topics=TOPICS)
    trial = ds["bag1"]
    el, wr = trial.streams["electrodes"], trial.streams["wrench"]
    np.testing.assert_allclose(np.arange(20) * 0.01, el["t"].to_numpy(), atol=1e-12)
    assert [1.0, 3.0, 6.0] == el.iloc[3][["data_0", "data_1", "data_2"]].tolist()
    np.testing.assert_allclose(np.arange(40) * 0.005, wr["t"].to_numpy(), atol=1e-12)
    assert [1.0, -2.0, 2.5, 0.0, 0.0, 0.25] == wr.iloc[5][list(WRENCH)].tolist()


def test_stamp_receive_uses_the_recording_time(tmp_path: Path) -> None:
    """stamp=receive times the wrenches by when they were recorded (3 ms late)."""
    ds = read_rosbag(
        make_bags(tmp_path / "bags", "mcap", n_bags=1), topics=TOPICS, stamp="receive"
    )
    t = ds["bag0"].streams["wrench"]["t"].to_numpy()
    np.testing.assert_allclose(0.003 + np.arange(40) * 0.005, t, atol=1e-12)


def test_topic_list_names_streams_and_fields_pick_channels(tmp_path: Path) -> None:
    """A topic list names streams after the topics; fields keeps only the given ones."""
    ds = read_rosbag(
        make_bags(tmp_path / "bags", "sqlite3", n_bags=1),
        topics=["/ft"],
        fields={"/ft": ["wrench.force"]},
        units="N",
    )
    spec = ds.streams["ft"]
    assert (("wrench.force.x", "wrench.force.y", "wrench.force.z"), {"N"}) == (
        spec.channels,
        set(spec.units.values()),
    )


def test_a_single_bag_takes_its_row_of_the_labels_beside_it(tmp_path: Path) -> None:
    """One bag of a folder imports alone, labelled by its row of labels.csv."""
    folder = make_bags(tmp_path / "bags", "ros1", labels=LABELS)
    ds = read_rosbag(folder / "bag1.bag", topics=TOPICS)
    assert (["bag1"], ["ball"]) == (ds.trial_ids, ds.trials["object"].tolist())


# -- trials cut from bags ------------------------------------------------------------------
def test_trials_table_cuts_bags(tmp_path: Path) -> None:
    """A (bag, trial, t_start_s, t_end_s) table cuts each bag; t starts at t_start_s."""
    folder = make_bags(tmp_path / "bags", "mcap", n_bags=2)
    table = tmp_path / "trials.csv"
    table.write_text(
        "bag,trial,t_start_s,t_end_s\n"
        "bag0,a,0.0,0.1\nbag0,b,0.1,0.2\nbag1,a,0.05,0.15\n",
        encoding="utf-8",
    )
    (folder / "labels.csv").write_text(
        "bag,trial,slip_onset_s\nbag0,a,0.02\nbag0,b,\nbag1,a,0.03\n", encoding="utf-8"
    )
    ds = read_rosbag(folder, topics=TOPICS, trials=table)
    assert ["bag0/a", "bag0/b", "bag1/a"] == ds.trial_ids
    el = ds["bag1/a"].streams["electrodes"]
    np.testing.assert_allclose(np.arange(10) * 0.01, el["t"].to_numpy(), atol=1e-12)
    assert [1.0, 5.0, 10.0] == el.iloc[0][["data_0", "data_1", "data_2"]].tolist()
    assert 10 == len(ds["bag0/b"].streams["electrodes"])
    assert 0.03 == ds["bag1/a"].labels["slip_onset_s"]


@pytest.mark.parametrize("kind", ["bool", "string"])
def test_marker_topic_cuts_bags(tmp_path: Path, kind: str) -> None:
    """A Bool (or String) marker cuts trials: a repeated true is one trial, false ends it."""
    msgs = recording(T0, n=40)
    if kind == "bool":
        values: list[Any] = [True, True, False, True, False]
        names = ["0", "1"]
    else:
        values = ["grasp", "grasp", "", "lift", ""]
        names = ["grasp", "lift"]
    marker = T["std_msgs/msg/Bool" if kind == "bool" else "std_msgs/msg/String"]
    for when, value in zip((0, 50, 100, 200, 300), values, strict=True):
        msgs.append(("/trial", T0 + when * MS + 1, marker(data=value)))
    write_bag(tmp_path / "b" / "run", "sqlite3", sorted(msgs, key=lambda m: m[1]))
    ds = read_rosbag(tmp_path / "b", topics=TOPICS, trial_topic="/trial")
    assert [f"run/{n}" for n in names] == ds.trial_ids
    first = ds[f"run/{names[0]}"].streams["electrodes"]
    assert (10, 1.0) == (len(first), first["data_1"].iloc[0])  # frames 1-10
    assert 10 == len(ds[f"run/{names[1]}"].streams["electrodes"])


# -- custom messages -------------------------------------------------------------------------
def custom_bag(folder: Path) -> Path:
    """An sqlite3 bag of a custom type whose definition is then removed from the bag."""
    store = get_typestore(Stores.LATEST)
    store.register(get_types_from_msg(CUSTOM_MSG, CUSTOM))
    taxels = store.types[CUSTOM]
    msgs = [
        ("/taxels", T0 + i * 2 * MS, taxels(pressure=np.float32([i, 1, 2]), count=i))
        for i in range(5)
    ]
    path = write_bag(folder / "custom", "sqlite3", msgs, store=store)
    db = next(path.glob("*.db3"))
    with sqlite3.connect(db) as con:
        con.execute("DELETE FROM message_definitions")
    return path


def test_custom_type_loads_from_msg_files(tmp_path: Path) -> None:
    """A type the bag does not define reads from the .msg file the user points to."""
    path = custom_bag(tmp_path / "bags")
    msg = tmp_path / "defs" / "slip_msgs" / "msg" / "Taxels.msg"
    msg.parent.mkdir(parents=True)
    msg.write_text(CUSTOM_MSG, encoding="utf-8")
    ds = read_rosbag(path, topics={"/taxels": "taxels"}, msg_files=[tmp_path / "defs"])
    spec = ds.streams["taxels"]
    assert (("pressure_0", "pressure_1", "pressure_2", "count"), 500.0) == (
        spec.channels,
        spec.rate_hz,
    )
    assert [4.0, 1.0, 2.0, 4.0] == ds.stream("taxels").iloc[4, 2:].tolist()


# -- bad input: one line naming bag, topic and message -----------------------------------
def bad_stamps(repeat: bool) -> list[Message]:
    msgs = recording(T0, n=6)
    stamp = T0 + (5 if repeat else 0) * MS  # wrench 2 repeats wrench 1's, or goes back
    return [
        (t, w, wrench(stamp, 0.0)) if t == "/ft" and w == T0 + 13 * MS else (t, w, m)
        for t, w, m in msgs
    ]


def joint_states() -> list[Message]:
    js = T["sensor_msgs/msg/JointState"]
    return [
        (
            "/joints",
            T0 + i * MS,
            js(
                header=header(T0 + i * MS),
                name=["a"],
                position=np.zeros(1),
                velocity=np.zeros(1),
                effort=np.zeros(1),
            ),
        )
        for i in range(3)
    ]


def growing_array() -> list[Message]:
    return [
        ("/biotac/electrodes", T0 + i * MS, electrodes([0.0] * (3 + (i == 2))))
        for i in range(4)
    ]


BAD_BAGS: list[tuple[str, Callable[[], list[Message]], dict[str, Any], str]] = [
    (
        "missing topic",
        lambda: recording(T0, n=4),
        {"topics": ["/biotac/pac"]},
        r"bag: no topic '/biotac/pac'; the bag's topics: /biotac/electrodes, /ft$",
    ),
    (
        "text field",
        joint_states,
        {"topics": ["/joints"]},
        r"bag: topic '/joints', message 0: field 'name' holds text, not numbers; "
        r"pick numeric fields with fields=\{/joints: \[\.\.\.\]\}$",
    ),
    (
        "text field picked",
        joint_states,
        {"topics": ["/joints"], "fields": {"/joints": ["position", "name"]}},
        r"bag: topic '/joints', message 0: field 'name' holds text, not numbers$",
    ),
    (
        "no such field",
        joint_states,
        {"topics": ["/joints"], "fields": {"/joints": ["torque"]}},
        r"topic '/joints', message 0: no field 'torque' \(sensor_msgs/msg/JointState "
        r"has fields header, name, position, velocity, effort\)$",
    ),
    (
        "repeated stamp",
        lambda: bad_stamps(repeat=True),
        {"topics": ["/ft"]},
        r"bag: topic '/ft', message 2: repeats the time of message 1 .*unset header",
    ),
    (
        "stamp going back",
        lambda: bad_stamps(repeat=False),
        {"topics": ["/ft"]},
        r"bag: topic '/ft', message 2: time 1700000000\.000000000 s is before message "
        r"1's \(1700000000\.005000000 s\); times must increase$",
    ),
    (
        "array length changes",
        growing_array,
        {"topics": ["/biotac/electrodes"]},
        r"topic '/biotac/electrodes', message 2: has 4 values \(data_0, data_1, data_2, "
        r"data_3\); message 0 had 3",
    ),
    (
        "one message",
        lambda: recording(T0, n=1)[:1],
        {"topics": ["/biotac/electrodes"]},
        r"topic '/biotac/electrodes': every trial holds one message; cannot estimate",
    ),
]


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize(
    ("messages", "options", "message"),
    [pytest.param(*case[1:], id=case[0]) for case in BAD_BAGS],
)
def test_bad_bag_is_one_line_naming_bag_topic_message(
    tmp_path: Path,
    storage: str,
    messages: Callable[[], list[Message]],
    options: dict[str, Any],
    message: str,
) -> None:
    """Each bad bag is one SourceFormatError naming the bag, topic and message index."""
    path = write_bag(bag_path(tmp_path, "bag", storage), storage, messages())
    with pytest.raises(SourceFormatError, match=message) as err:
        read_rosbag(path, **options)
    assert str(err.value).startswith(str(path))
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("storage", STORAGES)
@pytest.mark.parametrize("keep", [0.1, 0.5, 0.9])
def test_truncated_bag_is_one_line(tmp_path: Path, storage: str, keep: float) -> None:
    """A bag cut short (a recorder killed mid-write) is refused naming the bag."""
    path = write_bag(bag_path(tmp_path, "bag", storage), storage, recording(T0))
    data = (
        path
        if path.is_file()
        else next(p for p in path.iterdir() if p.suffix != ".yaml")
    )
    data.write_bytes(data.read_bytes()[: int(data.stat().st_size * keep)])
    with pytest.raises(
        SourceFormatError, match=r"bag(\.bag)?: cannot be read.*truncated or damaged\?$"
    ):
        read_rosbag(path, topics=TOPICS)


def test_undefined_custom_type_asks_for_msg_files(tmp_path: Path) -> None:
    """A type neither the bag nor ROS 2 defines names the topic and asks for its .msg."""
    path = custom_bag(tmp_path / "bags")
    with pytest.raises(
        SourceFormatError,
        match=r"custom: topic '/taxels' has message type slip_msgs/msg/Taxels, which "
        r"the bag does not define; give its \.msg file with msg_files=\[\.\.\.\]$",
    ):
        read_rosbag(path, topics=["/taxels"])


BAD_TABLES = [
    (
        "labels: no row",
        "labels.csv",
        "bag,slip_onset_s\nbag0,0.1\n",
        {},
        r"labels\.csv: no row for bag 'bag1'$",
    ),
    (
        "labels: unknown bag",
        "labels.csv",
        "bag,slip_onset_s\nbag0,0.1\nbag1,0.1\nbag7,0.2\n",
        {},
        r"labels\.csv: line 4, column 'bag': no bag 'bag7' here \(bags: bag0, bag1\)$",
    ),
    (
        "labels: text onset",
        "labels.csv",
        "bag,slip_onset_s\nbag0,0.1\nbag1,soon\n",
        {},
        r"labels\.csv: line 3, column 'slip_onset_s': 'soon' is not a number of seconds",
    ),
    (
        "labels: repeated bag",
        "labels.csv",
        "bag,object\nbag0,cube\nbag1,cube\nbag0,ball\n",
        {},
        r"labels\.csv: line 4: repeats the row of bag 'bag0' at line 2$",
    ),
    (
        "trials: end before start",
        "trials.csv",
        "bag,trial,t_start_s,t_end_s\nbag0,a,0.1,0.1\nbag1,a,0,0.1\n",
        {"trials": "trials.csv"},
        r"trials\.csv: line 2: t_end_s 0\.1 is not after t_start_s 0\.1$",
    ),
    (
        "trials: empty window",
        "trials.csv",
        "bag,trial,t_start_s,t_end_s\nbag0,a,0,0.1\nbag1,late,5,6\n",
        {"trials": "trials.csv"},
        r"trials\.csv: line 3: trial 'bag1/late' holds no message of topic "
        r"'/biotac/electrodes'$",
    ),
    (
        "trials: extra column",
        "trials.csv",
        "bag,trial,t_start_s,t_end_s,object\nbag0,a,0,0.1,cube\n",
        {"trials": "trials.csv"},
        r"trials\.csv: unexpected column 'object'; .*labels and groups go in labels\.csv",
    ),
]


@pytest.mark.parametrize(
    ("name", "text", "options", "message"),
    [pytest.param(*case[1:], id=case[0]) for case in BAD_TABLES],
)
def test_bad_table_is_one_line_naming_file_and_line(
    tmp_path: Path, name: str, text: str, options: dict[str, Any], message: str
) -> None:
    """A bad labels or trials table names the file, line and what is wrong."""
    folder = make_bags(tmp_path / "bags", "mcap", n_bags=2)
    table = (folder if name == "labels.csv" else tmp_path) / name
    table.write_text(text, encoding="utf-8")
    opts = {k: tmp_path / v for k, v in options.items()}
    with pytest.raises(SourceFormatError, match=message):
        read_rosbag(folder, topics=TOPICS, **opts)


# -- slipkit import / info -------------------------------------------------------------------
def test_cli_import_then_info(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`slipkit import source=rosbag` writes a dataset that `slipkit info` reads."""
    folder = make_bags(tmp_path / "bags", "mcap", labels=LABELS)
    out = tmp_path / "ds"
    main(
        [
            "import",
            "source=rosbag",
            f"path={folder}",
            f"out={out}",
            "source.sensor=biotac",
            "source.topics={/biotac/electrodes: electrodes, /ft: wrench}",
        ]
    )
    capsys.readouterr()
    main(["info", f"dataset={out}"])
    text = capsys.readouterr().out
    assert "trials    3" in text
    assert (True, True) == ("100 Hz" in text, "200 Hz" in text)
    ds = load_dataset(out)
    assert (3, "biotac", ("object",)) == (len(ds), ds.sensor, ds.groups)


def test_cli_bad_bag_is_one_line_and_writes_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A missing topic ends `slipkit import` with one line, exit 2, and no dataset."""
    folder = make_bags(tmp_path / "bags", "ros1", n_bags=1)
    out = tmp_path / "ds"
    with pytest.raises(SystemExit) as exc:
        main(
            [
                "import",
                "source=rosbag",
                f"path={folder}",
                f"out={out}",
                "source.topics=[/nope]",
            ]
        )
    err = capsys.readouterr().err.strip().splitlines()
    assert (2, 1) == (exc.value.code, len(err))
    assert err[0].startswith(
        f"slipkit import: error: {folder / 'bag0.bag'}: no topic '/nope'"
    )
    assert [] == sorted(p.name for p in tmp_path.iterdir() if p.name != "bags")


def test_cli_without_topics_says_what_to_give(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`source=rosbag` without topics names the option and an example."""
    folder = make_bags(tmp_path / "bags", "mcap", n_bags=1)
    with pytest.raises(SystemExit) as exc:
        main(["import", "source=rosbag", f"path={folder}", f"out={tmp_path / 'ds'}"])
    err = capsys.readouterr().err
    assert 2 == exc.value.code
    assert "error: topics is empty; name the topics that make the streams" in err
