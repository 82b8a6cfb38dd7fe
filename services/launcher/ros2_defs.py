"""ROS 2 message definitions (.msg text, ROS 2 Humble/Jazzy common_interfaces) of the types
mission.mcap carries, as the `ros2msg` schema text MCAP wants: the type's own definition,
then each type it uses after a line of 80 `=` and `MSG: pkg/Type`. Comments are left out;
field names, types and order are the public interface definitions'.
"""

from __future__ import annotations

SEPARATOR = "=" * 80

_DEFS: dict[str, str] = {
    "builtin_interfaces/Time": "int32 sec\nuint32 nanosec\n",
    "builtin_interfaces/Duration": "int32 sec\nuint32 nanosec\n",
    "std_msgs/Header": "builtin_interfaces/Time stamp\nstring frame_id\n",
    "std_msgs/ColorRGBA": "float32 r\nfloat32 g\nfloat32 b\nfloat32 a\n",
    "geometry_msgs/Point": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Vector3": "float64 x\nfloat64 y\nfloat64 z\n",
    "geometry_msgs/Quaternion": "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
    "geometry_msgs/Pose": "Point position\nQuaternion orientation\n",
    "geometry_msgs/PoseStamped": "std_msgs/Header header\nPose pose\n",
    "geometry_msgs/PoseWithCovariance": "Pose pose\nfloat64[36] covariance\n",
    "geometry_msgs/Twist": "Vector3 linear\nVector3 angular\n",
    "geometry_msgs/TwistWithCovariance": "Twist twist\nfloat64[36] covariance\n",
    "geometry_msgs/Transform": "Vector3 translation\nQuaternion rotation\n",
    "geometry_msgs/TransformStamped": (
        "std_msgs/Header header\nstring child_frame_id\nTransform transform\n"),
    "nav_msgs/Odometry": (
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\n"
        "geometry_msgs/TwistWithCovariance twist\n"),
    "nav_msgs/MapMetaData": (
        "builtin_interfaces/Time map_load_time\nfloat32 resolution\nuint32 width\n"
        "uint32 height\ngeometry_msgs/Pose origin\n"),
    "nav_msgs/OccupancyGrid": "std_msgs/Header header\nMapMetaData info\nint8[] data\n",
    "sensor_msgs/PointField": (
        "uint8 INT8    = 1\nuint8 UINT8   = 2\nuint8 INT16   = 3\nuint8 UINT16  = 4\n"
        "uint8 INT32   = 5\nuint8 UINT32  = 6\nuint8 FLOAT32 = 7\nuint8 FLOAT64 = 8\n"
        "string name\nuint32 offset\nuint8  datatype\nuint32 count\n"),
    "sensor_msgs/PointCloud2": (
        "std_msgs/Header header\nuint32 height\nuint32 width\nPointField[] fields\n"
        "bool    is_bigendian\nuint32  point_step\nuint32  row_step\nuint8[] data\n"
        "bool is_dense\n"),
    "sensor_msgs/CompressedImage": "std_msgs/Header header\nstring format\nuint8[] data\n",
    "tf2_msgs/TFMessage": "geometry_msgs/TransformStamped[] transforms\n",
    "visualization_msgs/UVCoordinate": "float32 u\nfloat32 v\n",
    "visualization_msgs/MeshFile": "string filename\nuint8[] data\n",
    "visualization_msgs/Marker": (
        "int32 ARROW=0\nint32 CUBE=1\nint32 SPHERE=2\nint32 CYLINDER=3\nint32 LINE_STRIP=4\n"
        "int32 LINE_LIST=5\nint32 CUBE_LIST=6\nint32 SPHERE_LIST=7\nint32 POINTS=8\n"
        "int32 TEXT_VIEW_FACING=9\nint32 MESH_RESOURCE=10\nint32 TRIANGLE_LIST=11\n"
        "int32 ARROW_STRIP=12\nint32 ADD=0\nint32 MODIFY=0\nint32 DELETE=2\nint32 DELETEALL=3\n"
        "std_msgs/Header header\nstring ns\nint32 id\nint32 type\nint32 action\n"
        "geometry_msgs/Pose pose\ngeometry_msgs/Vector3 scale\nstd_msgs/ColorRGBA color\n"
        "builtin_interfaces/Duration lifetime\nbool frame_locked\n"
        "geometry_msgs/Point[] points\nstd_msgs/ColorRGBA[] colors\nstring texture_resource\n"
        "sensor_msgs/CompressedImage texture\nUVCoordinate[] uv_coordinates\nstring text\n"
        "string mesh_resource\nMeshFile mesh_file\nbool mesh_use_embedded_materials\n"),
    "visualization_msgs/MarkerArray": "Marker[] markers\n",
}

_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16",
               "uint16", "int32", "uint32", "int64", "uint64", "string", "wstring"}


def _field_types(datatype: str) -> list[str]:
    """The full names of the message types `datatype`'s fields use (a bare name means the
    same package)."""
    package = datatype.split("/")[0]
    out = []
    for line in _DEFS[datatype].splitlines():
        words = line.split()
        if not words or "=" in line:  # a constant
            continue
        base = words[0].split("[")[0]
        if base in _PRIMITIVES:
            continue
        out.append(base if "/" in base else f"{package}/{base}")
    return out


def _dependencies(datatype: str) -> list[str]:
    """Every type `datatype` uses, depth first, each once."""
    seen: list[str] = []

    def visit(name: str) -> None:
        for dep in _field_types(name):
            if dep not in seen:
                seen.append(dep)
                visit(dep)

    visit(datatype)
    return seen


def schema_text(datatype: str) -> str:
    """The `ros2msg` schema of `datatype` (e.g. "nav_msgs/Odometry") with its dependencies."""
    parts = [_DEFS[datatype].rstrip("\n")]
    for dep in _dependencies(datatype):
        parts += [SEPARATOR, f"MSG: {dep}", _DEFS[dep].rstrip("\n")]
    return "\n".join(parts) + "\n"


TYPES = ("sensor_msgs/msg/PointCloud2", "nav_msgs/msg/OccupancyGrid", "nav_msgs/msg/Odometry",
         "tf2_msgs/msg/TFMessage", "visualization_msgs/msg/MarkerArray")


def short(datatype: str) -> str:
    """"pkg/msg/Type" → "pkg/Type" (the key of the definitions above)."""
    parts = datatype.split("/")
    return f"{parts[0]}/{parts[-1]}"
