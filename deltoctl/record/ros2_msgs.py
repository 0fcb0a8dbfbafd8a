"""ROS 2 message definitions the recorder writes (ros2msg text with its dependencies)."""

SEP = "=" * 80 + "\n"

TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
INTERFACE_VALUE = "MSG: control_msgs/InterfaceValue\nstring[] interface_names\nfloat64[] values\n"
KEY_VALUE = "MSG: diagnostic_msgs/KeyValue\nstring key\nstring value\n"
STATUS = ("MSG: diagnostic_msgs/DiagnosticStatus\nbyte OK=0\nbyte WARN=1\nbyte ERROR=2\n"
          "byte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\n"
          "diagnostic_msgs/KeyValue[] values\n")


def _join(main: str, *deps: str) -> str:
    return main + "".join(SEP + d for d in deps)


MSGDEFS = {
    "sensor_msgs/msg/JointState": _join(
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
        "float64[] effort\n", HEADER, TIME),
    "geometry_msgs/msg/WrenchStamped": _join(
        "std_msgs/Header header\ngeometry_msgs/Wrench wrench\n",
        "MSG: geometry_msgs/Wrench\ngeometry_msgs/Vector3 force\ngeometry_msgs/Vector3 torque\n",
        VECTOR3, HEADER, TIME),
    "sensor_msgs/msg/Imu": _join(
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
        "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
        "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
        "float64[9] linear_acceleration_covariance\n",
        HEADER, TIME, "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\n"
        "float64 w 1\n", VECTOR3),
    "control_msgs/msg/DynamicJointState": _join(
        "std_msgs/Header header\nstring[] joint_names\n"
        "control_msgs/InterfaceValue[] interface_values\n", INTERFACE_VALUE, HEADER, TIME),
    "control_msgs/msg/DynamicInterfaceGroupValues": _join(
        "std_msgs/Header header\nstring[] interface_groups\n"
        "control_msgs/InterfaceValue[] interface_values\n", INTERFACE_VALUE, HEADER, TIME),
    "diagnostic_msgs/msg/DiagnosticArray": _join(
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status\n",
        STATUS, KEY_VALUE, HEADER, TIME),
}


