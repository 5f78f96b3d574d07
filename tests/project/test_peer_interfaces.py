"""The peers' interface packages carry the peers' definitions, field for field.

A type at a boundary that OPERA (pwri-opera/com3_ros), the original (irvs/ros2_tms_for_construction), Nav2 (jazzy)
or ROS 2 geometry2 (jazzy) defines only matches the peer on DDS when package, name, field names, field types, order,
constants and defaults are identical. PEER holds the peer's field list for each type, written out here (not read from
our .msg files), and each test compares it with the class rosidl generated: a changed copy fails here.
"""

from __future__ import annotations

import importlib
import re

import pytest

# Peer definitions in .msg syntax; `---` separates request/response (srv) or goal/result/feedback (action).
# Comments are left out: only names, types, constants and defaults are the contract.
PEER: dict[str, str] = {
    # ---- pwri-opera/com3_ros, com3_msgs
    "com3_msgs/msg/JointCmd": """
        string[] joint_name
        uint8 control_type
        float64[] position
        float64[] velocity
        float64[] effort
    """,
    "com3_msgs/msg/ExcavatorCom3MachineSetting": """
        float64 engine_rpm
        bool power_eco_mode
        bool travel_speed_mode
        bool working_mode_notice
        uint8 yellow_led_mode
        uint8 front_control_mode
        uint8 tracks_control_mode
    """,
    "com3_msgs/msg/CrawlerCarrierCom3MachineSetting": """
        uint8 operation_mode
        uint8 velocity_mode
        bool swing_mode
        bool dump_mode
        bool eco_mode
        bool speed_mode
        bool engine_on
        uint8 state_number
        uint16 engine_rpm
    """,
    "com3_msgs/msg/FluidPressureArray": """
        sensor_msgs/FluidPressure[] array
    """,
    "com3_msgs/srv/DumpUp": """
        float64 vessel_angle
        ---
        bool result
    """,
    "com3_msgs/action/SetDumpAngle": """
        float64 target_angle
        ---
        bool success
        ---
        float64 current_error
    """,
    "com3_msgs/action/SetSwingAngle": """
        float64 target_angle
        ---
        bool success
        ---
        float64 current_error
    """,
    # ---- irvs/ros2_tms_for_construction, tms_msg/tms_msg_ts
    "tms_msg_ts/action/LeafNodeBase": """
        string model_name
        string record_name
        ---
        bool result
        ---
        string status
    """,
    "tms_msg_ts/action/ActionSample": """
        int32 goal_pos
        ---
        bool result
        ---
        int32 current_pos
    """,
    "tms_msg_ts/srv/BlackboardParameters": """
        string port_name
        ---
        int64 val
        float64 timestamp
    """,
    "tms_msg_ts/srv/TargetAngle": """
        float64 vessel_angle
        ---
        bool result
    """,
    # ---- irvs/ros2_tms_for_construction, tms_msg/tms_msg_rp
    "tms_msg_rp/msg/TmsRpErrorCodes": """
        int32 val
        int32 SUCCESS=1
        int32 FAILURE=99999
    """,
    "tms_msg_rp/msg/TmsRpZx200PositionWithAngle": """
        geometry_msgs/Point position
        float64 theta_w
        float64 offset
    """,
    "tms_msg_rp/action/TmsRpZx200ChangePose": """
        trajectory_msgs/JointTrajectory trajectory
        geometry_msgs/Pose[] pose_sequence
        tms_msg_rp/TmsRpZx200PositionWithAngle[] position_with_angle_sequence
        ---
        TmsRpErrorCodes error_code
        ---
        string state
    """,
    "tms_msg_rp/action/TmsRpZx200ExcavateSimple": """
        tms_msg_rp/TmsRpZx200PositionWithAngle position_with_angle
        ---
        TmsRpErrorCodes error_code
        ---
        string state
    """,
    "tms_msg_rp/action/TmsRpZx200ReleaseSimple": """
        float64 target_angle
        ---
        TmsRpErrorCodes error_code
        ---
        string state
    """,
    # ---- irvs/ros2_tms_for_construction, tms_msg/tms_msg_db
    "tms_msg_db/srv/TmsdbGetTask": """
        int32 task_id
        ---
        string task
    """,
    "tms_msg_db/srv/TmsdbGetParameter": """
        string model_name
        string record_name
        ---
        string[] keys
        string[] values
    """,
    "tms_msg_db/msg/Tmsdb": """
        string time
        string type
        int32 id
        string name
        string msg
    """,
    "tms_msg_db/msg/TmsdbQuery": """
        string time
        string type
        string writemode
        int32 id
        string record_name
        string vehicle_name
        string msg
        geometry_msgs/PoseStamped add_path
        sensor_msgs/JointState add_joints
    """,
    "tms_msg_db/msg/TmsdbGridFS": """
        string time
        string type
        int32 id
        string filename
        sensor_msgs/PointCloud2 pointcloud2
    """,
    "tms_msg_db/msg/TmsdbCollision": """
        string model_name
        string type
        string filepath
    """,
    "tms_msg_db/msg/TmsdbTerrainImageMsg": """
        string time
        string type
        int32 id
        string filename
        float32 terrainheight
        float32 terrainwidth
        float32 terrainelevation
        float32 offset_x
        float32 offset_y
        sensor_msgs/Image image
    """,
    "tms_msg_db/msg/ColoredMesh": """
        shape_msgs/MeshTriangle[] triangles
        geometry_msgs/Point[] vertices
        std_msgs/ColorRGBA[] vertex_colors
        geometry_msgs/Vector3[] vertex_normals
    """,
    "tms_msg_db/srv/TmsdbGetData": """
        string type
        int32 id
        bool latest_only
        string flgorparam
        string name
        string[] recordnames
        ---
        tms_msg_db/Tmsdb[] tmsdbs
    """,
    "tms_msg_db/srv/TmsdbGridFSGetData": """
        string type
        int32 id
        string filename
        ---
        bool result
    """,
    "tms_msg_db/srv/TerrainStaticSrv": """
        string type
        ---
        sensor_msgs/PointCloud2 pointcloud2
    """,
    "tms_msg_db/srv/DemSrv": """
        string type
        ---
        nav_msgs/OccupancyGrid occupancy_grid
    """,
    "tms_msg_db/srv/ColoredMeshSrv": """
        string type
        ---
        tms_msg_db/ColoredMesh colored_mesh
    """,
    "tms_msg_db/srv/TmsdbTerrainImageSrv": """
        string type
        int32 id
        string filename
        ---
        string time
        string type
        int32 id
        string filename
        float32 terrainheight
        float32 terrainwidth
        float32 terrainelevation
        float32 offset_x
        float32 offset_y
        sensor_msgs/Image image
    """,
    "tms_msg_db/action/TmsdbGridFS": """
        string type
        int32 id
        string filename
        bool latest_only
        ---
        bool result
        string msg
        sensor_msgs/PointCloud2 pointcloud2
        ---
        bool result
        string msg
        sensor_msgs/PointCloud2 pointcloud2
    """,
    "tms_msg_db/action/TmsdbTerrainImage": """
        string type
        int32 id
        string filename
        bool latest_only
        ---
        bool result
        string msg
        string time
        string type
        string filename
        float32 terrainheight
        float32 terrainwidth
        float32 terrainelevation
        float32 offset_x
        float32 offset_y
        sensor_msgs/Image image
        ---
        bool result
        string msg
        string time
        string type
        int32 id
        string filename
        float32 terrainheight
        float32 terrainwidth
        float32 terrainelevation
        float32 offset_x
        float32 offset_y
        sensor_msgs/Image image
    """,
    # ---- irvs/ros2_tms_for_construction, tms_msg/tms_msg_ur
    "tms_msg_ur/msg/Demo202412": """
        string task_sequence1
        string task_sequence2
    """,
    "tms_msg_ur/msg/TmsdbPoseWriteMsg": """
        string type
        string machine_name
        string machine_kinds
        string record_name
        string record_type
        string description
        string write_target
        geometry_msgs/PoseStamped pose
        sensor_msgs/JointState joints
    """,
    "tms_msg_ur/srv/TmsdbTerrainDBPoseWriteSrv": """
        string type
        string machine_name
        string machine_kinds
        string record_name
        string record_type
        string description
        string write_target
        geometry_msgs/PoseStamped pose
        sensor_msgs/JointState joints
        ---
        string id
        string log_data
        bool written
    """,
    # ---- irvs/ros2_tms_for_construction, tms_ts/sensing_msgs
    "sensing_msgs/msg/ChangePose": """
        string model_name
        string record_name
        float64 swing_joint
        float64 boom_joint
        float64 arm_joint
        float64 bucket_joint
        float64 bucket_end_joint
    """,
    "sensing_msgs/msg/DigCycle": """
        string model_name
        string record_name
        string dig_cycle
    """,
    "sensing_msgs/msg/ExcavateSimple": """
        string model_name
        string record_name
        float64 x
        float64 y
        float64 z
        float64 theta_w
    """,
    "sensing_msgs/msg/Flgs": """
        string record_name
        bool loaded_flg
        string[] keep_val_flgs
    """,
    "sensing_msgs/msg/Flgs202506": """
        string record_name
        bool continue_flg
        bool standby_excavation_flg
        bool standby_release_flg
        string[] keep_val_flgs
    """,
    "sensing_msgs/msg/Flgs202508": """
        string record_name
        bool continue_flg
        bool sensing_arrival_flg
        string[] keep_val_flgs
    """,
    "sensing_msgs/msg/FollowWaypoints": """
        string model_name
        string record_name
        float64[] x
        float64[] y
        float64[] z
        float64[] qx
        float64[] qy
        float64[] qz
        float64[] qw
    """,
    "sensing_msgs/msg/FollowWaypointsDeg": """
        string model_name
        string record_name
        float64[] x
        float64[] y
        float64[] z
        float64[] yaw
    """,
    "sensing_msgs/msg/NavigateAnywhereDeg": """
        string model_name
        string record_name
        float64 x
        float64 y
        float64 z
        float64 yaw
    """,
    "sensing_msgs/msg/NavigateThroughPoses": """
        string model_name
        string record_name
        float64[] x
        float64[] y
        float64[] z
        float64 qx
        float64 qy
        float64 qz
        float64 qw
    """,
    "sensing_msgs/msg/NavigateThroughPosesDeg": """
        string model_name
        string record_name
        float64[] x
        float64[] y
        float64[] z
        float64 yaw
    """,
    "sensing_msgs/msg/ReleaseLocations": """
        string model_name
        string record_name
        string num
    """,
    "sensing_msgs/msg/ReleaseSimple": """
        string model_name
        string record_name
        int64 position_with_angle
        float64 x
        float64 y
        float64 z
        float64 theta_w
    """,
    "sensing_msgs/msg/ReleaseSoil": """
        string model_name
        string record_name
        float64 target_angle
    """,
    "sensing_msgs/msg/Sample": """
        string model_name
        string record_name
        int32 sample_parameter_value
    """,
    "sensing_msgs/msg/Zx200CollisionObjectsIc120": """
        string model_name
        string record_name
        float64 x
        float64 y
        float64 z
        float64 qx
        float64 qy
        float64 qz
        float64 qw
    """,
    "sensing_msgs/msg/Zx200EndEffector": """
        string model_name
        string record_name
        float32 x
        float32 y
        float32 z
        float32 theta_w
    """,
    "sensing_msgs/msg/DigLocations": """
        string model_name
        string record_name
        string num
    """,
    "sensing_msgs/msg/NavigateAnywhere": """
        string model_name
        string record_name
        float64 x
        float64 y
        float64 z
        float64 qx
        float64 qy
        float64 qz
        float64 qw
    """,
    "sensing_msgs/msg/ReleaseAngle": """
        string model_name
        string record_name
        float64 target_angle
    """,
    # ---- ros-navigation/navigation2 (jazzy), nav2_msgs
    "nav2_msgs/msg/MissedWaypoint": """
        uint32 index
        geometry_msgs/PoseStamped goal
        uint16 error_code
    """,
    "nav2_msgs/action/NavigateToPose": """
        geometry_msgs/PoseStamped pose
        string behavior_tree
        ---
        uint16 NONE=0
        uint16 error_code
        string error_msg
        ---
        geometry_msgs/PoseStamped current_pose
        builtin_interfaces/Duration navigation_time
        builtin_interfaces/Duration estimated_time_remaining
        int16 number_of_recoveries
        float32 distance_remaining
    """,
    "nav2_msgs/action/NavigateThroughPoses": """
        geometry_msgs/PoseStamped[] poses
        string behavior_tree
        ---
        uint16 NONE=0
        uint16 error_code
        string error_msg
        ---
        geometry_msgs/PoseStamped current_pose
        builtin_interfaces/Duration navigation_time
        builtin_interfaces/Duration estimated_time_remaining
        int16 number_of_recoveries
        float32 distance_remaining
        int16 number_of_poses_remaining
    """,
    "nav2_msgs/action/FollowWaypoints": """
        uint32 number_of_loops
        uint32 goal_index 0
        geometry_msgs/PoseStamped[] poses
        ---
        uint16 NONE=0
        uint16 UNKNOWN=600
        uint16 TASK_EXECUTOR_FAILED=601
        MissedWaypoint[] missed_waypoints
        uint16 error_code
        string error_msg
        ---
        uint32 current_waypoint
    """,
    # ---- ros2/geometry2 (jazzy), tf2_msgs
    "tf2_msgs/msg/TFMessage": """
        geometry_msgs/TransformStamped[] transforms
    """,
    "tf2_msgs/msg/TF2Error": """
        uint8 NO_ERRORS=0
        uint8 LOOKUP_ERROR=1
        uint8 CONNECTIVITY_ERROR=2
        uint8 EXTRAPOLATION_ERROR=3
        uint8 INVALID_ARGUMENT_ERROR=4
        uint8 TIMEOUT_ERROR=5
        uint8 TRANSFORM_ERROR=6
        uint8 error
        string error_string
    """,
    "tf2_msgs/srv/FrameGraph": """
        ---
        string frame_yaml
    """,
    "tf2_msgs/action/LookupTransform": """
        string target_frame
        string source_frame
        builtin_interfaces/Time source_time
        builtin_interfaces/Duration timeout
        builtin_interfaces/Time target_time
        string fixed_frame
        bool advanced
        ---
        geometry_msgs/TransformStamped transform
        tf2_msgs/TF2Error error
        ---
    """,
}

# .msg primitive names -> the type names rosidl's Python classes report.
_PRIMITIVE = {
    "bool": "boolean",
    "byte": "octet",
    "char": "uint8",
    "float32": "float",
    "float64": "double",
    "string": "string",
    **{t: t for t in ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64")},
}
_LINE = re.compile(
    r"^(?P<type>[\w/]+)(?P<array>\[\d*\])?\s+(?P<name>\w+)\s*(?:(?P<const>=)\s*(?P<cval>\S+)|(?P<dval>\S+))?$"
)


def _literal(text: str, base: str) -> object:
    if base == "string":
        return text.strip("'\"")
    if base == "bool":
        return text.lower() == "true"
    return float(text) if base.startswith("float") else int(text)


def _parse(section: str, package: str) -> tuple[list[tuple[str, str]], dict[str, object], dict[str, object]]:
    """(fields [(name, rosidl type)], constants, defaults) of one section in .msg syntax."""
    fields: list[tuple[str, str]] = []
    constants: dict[str, object] = {}
    defaults: dict[str, object] = {}
    for raw in section.strip().splitlines():
        line = raw.strip()
        if not line:
            continue
        m = _LINE.match(line)
        assert m, f"PEER table line not understood: {line!r}"
        base, name = m["type"], m["name"]
        if m["const"]:
            constants[name] = _literal(m["cval"], base)
            continue
        if base in _PRIMITIVE:
            typ = _PRIMITIVE[base]
        else:
            typ = base if "/" in base else f"{package}/{base}"
        array = m["array"]
        if array == "[]":
            typ = f"sequence<{typ}>"
        elif array:
            typ = f"{typ}{array}"
        fields.append((name, typ))
        if m["dval"] is not None:
            defaults[name] = _literal(m["dval"], base)
    return fields, constants, defaults


def _parts(key: str) -> list[tuple[type, str]]:
    """The generated classes of a type with the PEER section each must match."""
    package, kind, name = key.split("/")
    cls = getattr(importlib.import_module(f"{package}.{kind}"), name)
    sections = PEER[key].split("---")
    names = {"msg": [""], "srv": ["Request", "Response"], "action": ["Goal", "Result", "Feedback"]}[kind]
    assert len(sections) == len(names), f"{key}: PEER table has {len(sections)} sections, a {kind} has {len(names)}"
    return [(cls if not part else getattr(cls, part), section) for part, section in zip(names, sections, strict=True)]


def _constants(cls: type) -> dict[str, object]:
    meta = type(cls)
    return dict(getattr(meta, f"_{meta.__name__}__constants"))


@pytest.mark.parametrize("key", sorted(PEER))
def test_peer_type_matches_the_peers_definition(key):
    package = key.split("/")[0]
    for cls, section in _parts(key):
        fields, constants, defaults = _parse(section, package)
        got = list(cls.get_fields_and_field_types().items())
        assert got == fields, f"{key} {cls.__name__}: fields {got} differ from the peer's {fields}"
        assert _constants(cls) == constants, (
            f"{key} {cls.__name__}: constants {_constants(cls)} differ from the peer's {constants}"
        )
        instance = cls()
        for field, value in defaults.items():
            assert getattr(instance, field) == value, (
                f"{key} {cls.__name__}.{field}: default differs from the peer's {value!r}"
            )


def test_table_covers_every_type_the_peer_packages_hold():
    """Every interface file in a peer package is in PEER, so a type added to a package gets checked too."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    found = set()
    for package in (
        "com3_msgs", "tms_msg_ts", "tms_msg_rp", "tms_msg_db", "tms_msg_ur", "sensing_msgs", "nav2_msgs", "tf2_msgs"
    ):
        for kind in ("msg", "srv", "action"):
            for path in (root / package / kind).glob(f"*.{kind}"):
                found.add(f"{package}/{kind}/{path.stem}")
    assert found == set(PEER), (
        f"not in PEER: {sorted(found - set(PEER))}; in PEER without a file: {sorted(set(PEER) - found)}"
    )


def test_a_changed_copy_fails_the_comparison():
    """The comparison itself catches a renamed field, a changed type and a changed constant."""
    from com3_msgs.msg import JointCmd
    from nav2_msgs.action import NavigateToPose

    fields, _, _ = _parse(PEER["com3_msgs/msg/JointCmd"].replace("joint_name", "joint_names"), "com3_msgs")
    assert list(JointCmd.get_fields_and_field_types().items()) != fields
    fields, _, _ = _parse(
        PEER["com3_msgs/msg/JointCmd"].replace("uint8 control_type", "int8 control_type"), "com3_msgs"
    )
    assert list(JointCmd.get_fields_and_field_types().items()) != fields
    result = PEER["nav2_msgs/action/NavigateToPose"].split("---")[1].replace("NONE=0", "NONE=1")
    assert _constants(NavigateToPose.Result) != _parse(result, "nav2_msgs")[1]
