"""The ROS 2 message definitions a recording uses, as ``.msg`` text.

An MCAP file of the ``ros2`` profile carries, in each schema record, the definition of
its message type followed by those of the types it uses, each after a line of ``=`` and
``MSG: package/Type`` (the ``ros2msg`` schema encoding, as ``ros2 bag record`` writes
it). The fields below are those of the ROS 2 interfaces of Humble and later
(``common_interfaces``, ``rcl_interfaces``; comments and default values left out); a
reader decodes the messages with these definitions, and a subscriber of ``ros2 bag play``
with its own, so they must agree field for field (the tests compare them with the
definitions ``rosbags`` ships for Humble and Jazzy).
"""

from __future__ import annotations

__all__ = ["DEFINITIONS", "definition"]

#: each type's own fields (its dependencies are appended by :func:`definition`)
DEFINITIONS: dict[str, str] = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec",
    "builtin_interfaces/msg/Duration": "int32 sec\nuint32 nanosec",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "std_msgs/msg/ColorRGBA": "float32 r\nfloat32 g\nfloat32 b\nfloat32 a",
    "std_msgs/msg/Float64": "float64 data",
    "std_msgs/msg/MultiArrayDimension": "string label\nuint32 size\nuint32 stride",
    "std_msgs/msg/MultiArrayLayout": "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset",
    "std_msgs/msg/Float64MultiArray": "std_msgs/MultiArrayLayout layout\nfloat64[] data",
    "geometry_msgs/msg/Point": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/msg/Quaternion": "float64 x\nfloat64 y\nfloat64 z\nfloat64 w",
    "geometry_msgs/msg/Pose": "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation",
    "geometry_msgs/msg/PoseArray": "std_msgs/Header header\ngeometry_msgs/Pose[] poses",
    "geometry_msgs/msg/PoseStamped": "std_msgs/Header header\ngeometry_msgs/Pose pose",
    "sensor_msgs/msg/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data",
    "visualization_msgs/msg/UVCoordinate": "float32 u\nfloat32 v",
    "visualization_msgs/msg/MeshFile": "string filename\nuint8[] data",
    "visualization_msgs/msg/Marker": """\
int32 ARROW=0
int32 CUBE=1
int32 SPHERE=2
int32 CYLINDER=3
int32 LINE_STRIP=4
int32 LINE_LIST=5
int32 CUBE_LIST=6
int32 SPHERE_LIST=7
int32 POINTS=8
int32 TEXT_VIEW_FACING=9
int32 MESH_RESOURCE=10
int32 TRIANGLE_LIST=11
int32 ADD=0
int32 MODIFY=0
int32 DELETE=2
int32 DELETEALL=3
std_msgs/Header header
string ns
int32 id
int32 type
int32 action
geometry_msgs/Pose pose
geometry_msgs/Vector3 scale
std_msgs/ColorRGBA color
builtin_interfaces/Duration lifetime
bool frame_locked
geometry_msgs/Point[] points
std_msgs/ColorRGBA[] colors
string texture_resource
sensor_msgs/CompressedImage texture
visualization_msgs/UVCoordinate[] uv_coordinates
string text
string mesh_resource
visualization_msgs/MeshFile mesh_file
bool mesh_use_embedded_materials""",
    "visualization_msgs/msg/MarkerArray": "visualization_msgs/Marker[] markers",
}

#: the line between two definitions of a schema
SEPARATOR = "=" * 80


def _long(name: str) -> str:
    """``"std_msgs/Header"`` (as fields name it) -> ``"std_msgs/msg/Header"``."""
    package, _, short = name.partition("/")
    return name if "/msg/" in name else f"{package}/msg/{short}"


def _uses(text: str) -> list[str]:
    """The message types the fields of ``text`` use, in order of appearance."""
    out = []
    for line in text.splitlines():
        kind = line.split()[0].split("[")[0]
        if "/" in kind and "=" not in line:
            out.append(_long(kind))
    return out


def definition(name: str) -> str:
    """The schema text of ``name`` (e.g. ``"geometry_msgs/msg/PoseArray"``): its fields, then
    every type it uses, depth first, each once, after a separator and ``MSG: pkg/Type``."""
    order: list[str] = []

    def visit(kind: str) -> None:
        for used in _uses(DEFINITIONS[kind]):
            if used not in order:
                order.append(used)
                visit(used)

    visit(name)
    parts = [DEFINITIONS[name]]
    for used in order:
        package, _, short = used.partition("/msg/")
        parts.append(f"{SEPARATOR}\nMSG: {package}/{short}\n{DEFINITIONS[used]}")
    return "\n".join(parts) + "\n"
