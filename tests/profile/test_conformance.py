"""ros2_control conformance: the URDFs of ros2_control's own parser tests, loaded by deltoctl.

Each case joins pieces of ros2_control_test_assets (tests/conformance/assets, see its
LICENSE-NOTICE) the way hardware_interface/test/test_component_parser.cpp joins them. What a case
must give was written here from that test and from hardware_interface/src/component_parser.cpp:

- a valid case loads (through the catalog, as every verb loads a profile) into exactly the
  blocks, components, interfaces, params, rw_rate/async settings, mimic joints, transmissions,
  joint limits and soft limits ros2_control computes, with the warnings listed;
- an invalid case exits 2 with ``file:line:`` and a message naming what ros2_control names.

A few cases go beyond the parser test: the other snippets of the assets, and whole descriptions
other ros2_control tests load; their verdict is component_parser's (or, where said, the resource
manager's).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest

from deltoctl.profile.catalog import load_profile
from deltoctl.profile.model import (
    AsyncParams,
    Component,
    Interface,
    Limits,
    Profile,
    SoftLimits,
    Transmission,
    TransmissionEnd,
)

ASSETS = Path(__file__).parent.parent / "conformance" / "assets"
PI = 3.14159265359


# -- what a case expects -------------------------------------------------------------------------

def Itf(name: str, min: float | None = None, max: float | None = None,
      initial: str | None = None, params: dict[str, str] | None = None,
      data_type: str = "double", size: int = 1, enable: bool = True) -> dict[str, Any]:
    """An interface as ros2_control's InterfaceInfo holds it (``enable``: its limits are on)."""
    return {"name": name, "min": min, "max": max, "initial": initial, "params": params or {},
            "data_type": data_type, "size": size, "enable": enable}


def C(name: str, cmd: tuple = (), state: tuple = (),
      params: dict[str, str] | None = None) -> dict[str, Any]:
    """A joint, sensor or GPIO: its interfaces in order (a bare name: no details)."""
    return {"name": name, "cmd": [Itf(i) if isinstance(i, str) else i for i in cmd],
            "state": [Itf(i) if isinstance(i, str) else i for i in state], "params": params or {}}


def B(name: str, type: str, plugin: str, *, group: str | None = None,
      params: dict[str, str] | None = None, joints: tuple = (), sensors: tuple = (),
      gpios: tuple = (), limits: dict | None = None, soft: dict | None = None,
      transmissions: tuple = (), mimic: tuple = (), rw_rate: int = 0,
      async_params: AsyncParams | None = None) -> dict[str, Any]:
    """A block as ros2_control's HardwareInfo holds it. ``limits`` covers every joint (None:
    no limit at all); ``soft`` only the joints that have soft limits."""
    return {"name": name, "type": type, "plugin": plugin, "group": group, "params": params or {},
            "joints": list(joints), "sensors": list(sensors), "gpios": list(gpios),
            "limits": limits or {}, "soft": soft or {}, "transmissions": list(transmissions),
            "mimic": list(mimic), "rw_rate": rw_rate, "async": async_params}


def L(lower: float | None, upper: float | None, velocity: float | None, effort: float | None,
      **derivatives: float) -> Limits:
    return Limits(lower, upper, velocity, effort, **derivatives)


def S(lower: float, upper: float, k_position: float, k_velocity: float) -> SoftLimits:
    return SoftLimits(lower, upper, k_position, k_velocity)


def T(name: str, type: str, joints: tuple, actuators: tuple = (),
      params: dict[str, str] | None = None) -> Transmission:
    return Transmission(name, type, list(joints), list(actuators), params or {})


def E(name: str, role: str, reduction: float = 1.0, offset: float = 0.0, *,
      read_only: bool = False, cmd: tuple = (), state: tuple = (),
      implicit: bool = False) -> TransmissionEnd:
    """A transmission joint or actuator (``cmd``/``state``: the interface names filled in)."""
    return TransmissionEnd(name, role, reduction, offset, read_only, list(cmd), list(state),
                           implicit)


def P(write: str | None = "2", read: str | None = "2") -> dict[str, str]:
    """The example_param_* hardware params most assets carry."""
    params = {}
    if write is not None:
        params["example_param_write_for_sec"] = write
    if read is not None:
        params["example_param_read_for_sec"] = read
    return params


@dataclass
class Case:
    id: str
    parts: tuple[str, ...]
    blocks: list[dict[str, Any]] | None = None  # valid: what it loads into
    words: tuple[str, ...] = ()  # invalid: what the message must name
    warnings: tuple[str, ...] = ()  # valid: a part of each warning deltoctl gives, in order
    interfaces: tuple[list[str], list[str]] | None = None  # (state, command) full names
    note: str = ""

    @property
    def valid(self) -> bool:
        return self.blocks is not None


def urdf(*snippets: str, head: str = "urdf_head") -> tuple[str, ...]:
    return (head, *snippets, "urdf_tail")


# -- the blocks several cases share ----------------------------------------------------------------

HEAD = L(-PI, PI, 0.2, 0.1)  # urdf_head's joint1..3: <limit effort=0.1 ±π velocity=0.2>
RANGE = L(-1, 1, 0.2, 0.1)  # … with a position command interface of min -1, max 1
SOFT2 = S(-1.5, 0.5, 10, 20)  # joint2's <safety_controller>
SOFT2_IN_RANGE = S(-1, 0.5, 10, 20)  # … clamped into [-1, 1]
POS = Itf("position", -1, 1)
VEL = Itf("velocity", -1, 1)


def rrbot(name: str, plugin: str, **kwargs: Any) -> dict[str, Any]:
    """Two joints with a position command of [-1, 1]: the RRBot of many assets."""
    return B(name, "system", plugin, params=P(), joints=(
        C("joint1", (POS,), ("position",)), C("joint2", (POS,), ("position",))),
        limits={"joint1": RANGE, "joint2": RANGE}, soft={"joint2": SOFT2_IN_RANGE}, **kwargs)


def hardware_resources(transmissions: bool = False, rw_rates: tuple[int, int, int] = (0, 0, 0),
                   async_params: tuple = (None, None, None)) -> list[dict[str, Any]]:
    """descriptions.hpp's hardware_resources (and its rw_rate and async variants)."""
    joint1 = ("position", "max_velocity"), ("position", "velocity")
    joint2 = ("velocity", "max_acceleration"), ("position", "velocity", "acceleration")
    joint3 = ("velocity",), ("position", "velocity", "acceleration")
    actuator_trans, system_trans = (), ()
    if transmissions:
        actuator_trans = (T("ros2_control_transmission1", "transmission_interface/SimpleTransmission",
                            (E("joint1", "joint1", 325.949, cmd=joint1[0], state=joint1[1]),),
                            (E("actuator1", "actuator1", cmd=joint1[0], state=joint1[1],
                               implicit=True),)),)
        ends = ((E("joint2", "joint1", 2.0, 0.5, cmd=joint2[0], state=joint2[1]),
                 E("joint3", "joint2", -2.0, -0.5, cmd=joint3[0], state=joint3[1])),
                (E("joint2_motor", "actuator1", 50), E("joint3_motor", "actuator2", -50)))
        system_trans = (
            T("differential_transmission", "transmission_interface/DifferentialTransmission", *ends),
            T("four_bar_transmission", "transmission_interface/FourBarLinkageTransmission", *ends))
    return [
        B("TestActuatorHardware", "actuator", "test_actuator", joints=(C("joint1", *joint1),),
          limits={"joint1": HEAD}, transmissions=actuator_trans, rw_rate=rw_rates[0],
          async_params=async_params[0]),
        B("TestSensorHardware", "sensor", "test_sensor", params=P(),
          sensors=(C("sensor1", (), ("velocity",)),), rw_rate=rw_rates[1],
          async_params=async_params[1]),
        B("TestSystemHardware", "system", "test_system", params=P(),
          joints=(C("joint2", *joint2), C("joint3", *joint3)),
          gpios=(C("configuration", ("max_tcp_jerk",), ("max_tcp_jerk",)),),
          limits={"joint2": HEAD, "joint3": HEAD}, soft={"joint2": SOFT2},
          transmissions=system_trans, rw_rate=rw_rates[2], async_params=async_params[2]),
    ]


def gripper(left_cmd: tuple = (), mimic: tuple = ((1, 0, 2.0, 1.0),)) -> list[dict[str, Any]]:
    """The gripper of the mimic tests: a block with no <hardware>, so no plugin."""
    fingers = L(0, 0.38, 10, 1000)
    return [B("TestGripper", "system", "", joints=(
        C("right_finger_joint", ("effort",), ("position", "velocity", "effort")),
        C("left_finger_joint", left_cmd, ("position", "velocity"))),
        limits={"right_finger_joint": fingers, "left_finger_joint": fingers}, mimic=mimic)]


NO_HARDWARE = "has no <hardware>"
DISABLED_JOINT1 = C("joint1", (
    Itf("position", -1, 1, enable=False), Itf("velocity", -0.05, 0.1), Itf("effort", -0.2, 0.2),
    Itf("acceleration", -0.5, 0.5), Itf("jerk", max=5.0)), ("position",))
DISABLED_JOINT1_LIMITS = L(None, None, 0.05, 0.1, acceleration=0.5, deceleration=0.5, jerk=5.0)
FLANGE_IOS = C("flange_IOS", (Itf("digital_output", data_type="bool", size=2),),
               (Itf("analog_input", size=3), Itf("image", data_type="cv::Mat")))
CV_MAT = "unknown data_type 'cv::Mat'"
ALL_INTERFACES_JOINT1 = C("joint1", (
    POS, Itf("velocity", -0.05, 0.1), Itf("effort", -0.2, 0.2), Itf("acceleration", -0.5, 0.5),
    Itf("jerk", max=5.0)), ("position",))


def all_interfaces(joint1: Limits, joint2: Limits | None) -> list[dict[str, Any]]:
    """valid_urdf_ros2_control_system_robot_with_all_interfaces on a head with continuous
    joints."""
    return [B("RRBotSystemWithGPIO", "system",
              "ros2_control_demo_hardware/RRBotSystemWithGPIOHardware", params=P(), joints=(
                  ALL_INTERFACES_JOINT1,
                  C("joint2", ("position", "velocity", "effort", "acceleration", "jerk"),
                    ("position",))),
              limits={"joint1": joint1, "joint2": joint2})]


def actuator_only(state: tuple) -> list[dict[str, Any]]:
    """An actuator block with a transmission of the one joint, and the implicit actuator1."""
    return [B("ActuatorModularJoint1", "actuator",
              "ros2_control_demo_hardware/VelocityActuatorHardware", params=P("1.13", "3"),
              joints=(C("joint1", (VEL,), state),), limits={"joint1": HEAD},
              transmissions=(T("transmission1", "transmission_interface/RotationToLinerTansmission",
                               (E("joint1", "joint1", 325.949, cmd=("velocity",), state=state),),
                               (E("actuator1", "actuator1", cmd=("velocity",), state=state,
                                  implicit=True),),
                               {"additional_special_parameter": "1337"}),))]


# -- the cases -----------------------------------------------------------------------------------

VALID = [
    Case("system_one_interface", urdf("valid_urdf_ros2_control_system_one_interface"), [
        rrbot("RRBotSystemPositionOnly",
              "ros2_control_demo_hardware/RRBotSystemPositionOnlyHardware")]),
    Case("system_multi_interface", urdf("valid_urdf_ros2_control_system_multi_interface"), [
        B("RRBotSystemMultiInterface", "system",
          "ros2_control_demo_hardware/RRBotSystemMultiInterfaceHardware", params=P(), joints=(
              C("joint1", (Itf("position", -1, 1, "1.2"), Itf("velocity", -1, 1, "3.4"),
                           # max is '0.5"': ros2_control skips the pair, it stays text
                           Itf("effort", params={"min": "-0.5", "max": '0.5"'})),
                ("position", "velocity", "effort")),
              C("joint2", (POS,), ("position", "velocity", "effort"))),
          limits={"joint1": RANGE, "joint2": RANGE}, soft={"joint2": SOFT2_IN_RANGE})],
         warnings=("min/max of joint1/effort",)),
    Case("system_robot_with_sensor", urdf("valid_urdf_ros2_control_system_robot_with_sensor"), [
        rrbot("RRBotSystemWithSensor", "ros2_control_demo_hardware/RRBotSystemWithSensorHardware",
              sensors=(C("tcp_fts_sensor", (), ("fx", "fy", "fz", "tx", "ty", "tz"),
                         {"frame_id": "kuka_tcp", "lower_limits": "-100",
                          "upper_limits": "100"}),))]),
    Case("system_multi_interface_custom_interface_parameters", urdf(
        "valid_urdf_ros2_control_system_multi_interface_and_custom_interface_parameters"), [
        B("RRBotSystemMultiInterface", "system",
          "ros2_control_demo_hardware/RRBotSystemMultiInterfaceHardware", params=P(), joints=(
              C("joint1", (
                  Itf("position", -1, 1, "1.2", {"register": "1", "register_size": "2"}),
                  Itf("velocity", -1.5, 1.5, "3.4", {"register": "2", "register_size": "4"}),
                  Itf("effort", -0.5, 0.5)), (
                  Itf("position", params={"register": "3", "register_size": "2"}),
                  Itf("velocity", params={"register": "4", "register_size": "4"}), "effort"),
                {"modbus_server_ip": "1.1.1.1", "modbus_server_port": "1234",
                 "use_persistent_connection": "true"}),
              # data_type given as a <param> is a param, not the interface's data type
              C("joint2", (Itf("position", -1, 1, params={"register": "20",
                                                         "data_type": "int32_t"}),), (
                  Itf("position", params={"register": "21", "data_type": "int32_t"}), "velocity",
                  Itf("effort", params={"register": "21", "data_type": "int32_t"})),
                {"modbus_server_ip": "192.168.178.123", "modbus_server_port": "4321"})),
          limits={"joint1": RANGE, "joint2": RANGE}, soft={"joint2": SOFT2_IN_RANGE})]),
    Case("system_robot_with_external_sensor",
         urdf("valid_urdf_ros2_control_system_robot_with_external_sensor"), [
             rrbot("RRBotSystemPositionOnlyWithExternalSensor",
                   "ros2_control_demo_hardware/RRBotSystemPositionOnlyHardware"),
             B("RRBotForceTorqueSensor2D", "sensor",
               "ros2_control_demo_hardware/ForceTorqueSensor2DHardware",
               params={"example_param_read_for_sec": "0.43"},
               sensors=(C("tcp_fts_sensor", (), ("fx", "fy", "fz", "tx", "ty", "tz"),
                          {"frame_id": "kuka_tcp", "lower_limits": "-100",
                           "upper_limits": "100"}),))]),
    Case("actuator_modular_robot", urdf("valid_urdf_ros2_control_actuator_modular_robot"), [
        B(f"RRBotModularJoint{n}", "actuator", "ros2_control_demo_hardware/PositionActuatorHardware",
          group="Hardware Group", params=P("1.23", "3"),
          joints=(C(f"joint{n}", (POS,), ("position",)),), limits={f"joint{n}": RANGE},
          soft={"joint2": SOFT2_IN_RANGE} if n == 2 else None) for n in (1, 2)]),
    # the same joints in actuator blocks and in sensor blocks (modular robots)
    Case("actuator_modular_robot_sensors",
         urdf("valid_urdf_ros2_control_actuator_modular_robot_sensors"), [
             B("RRBotModularJoint1", "actuator",
               "ros2_control_demo_hardware/VelocityActuatorHardware", group="Hardware Group 1",
               params=P("1.23", "3"), joints=(C("joint1", (VEL,), ("velocity",)),),
               limits={"joint1": HEAD}, transmissions=(
                   T("transmission1", "transmission_interface/SimpleTansmission",
                     (E("joint1", "joint1", 325.949, cmd=("velocity",), state=("velocity",)),),
                     (E("actuator1", "actuator1", cmd=("velocity",), state=("velocity",),
                        implicit=True),)),)),
             B("RRBotModularJoint2", "actuator",
               "ros2_control_demo_hardware/VelocityActuatorHardware", group="Hardware Group 2",
               params=P("1.23", "3"), joints=(C("joint2", (VEL,), ("velocity",)),),
               limits={"joint2": HEAD}, soft={"joint2": SOFT2}),
             B("RRBotModularPositionSensorJoint1", "sensor",
               "ros2_control_demo_hardware/PositionSensorHardware", group="Hardware Group 1",
               params=P(None, "2"), joints=(C("joint1", (), ("position",)),),
               limits={"joint1": HEAD}),
             B("RRBotModularPositionSensorJoint2", "sensor",
               "ros2_control_demo_hardware/PositionSensorHardware", group="Hardware Group 2",
               params=P(None, "2"), joints=(C("joint2", (), ("position",)),),
               limits={"joint2": HEAD}, soft={"joint2": SOFT2})]),
    Case("system_multi_joints_transmission",
         urdf("valid_urdf_ros2_control_system_multi_joints_transmission"), [
             B("RRBotModularWrist", "system", "ros2_control_demo_hardware/ActuatorHardwareMultiDOF",
               params=P("1.23", "3"),
               joints=(C("joint1", (POS,), ("position",)), C("joint2", (POS,), ("position",))),
               limits={"joint1": RANGE, "joint2": RANGE}, soft={"joint2": SOFT2_IN_RANGE},
               transmissions=(T("transmission1", "transmission_interface/DifferentialTransmission",
                                (E("joint1", "joint1", 10, 0.5, cmd=("position",),
                                   state=("position",)),
                                 E("joint2", "joint2", 50, cmd=("position",),
                                   state=("position",))),
                                (E("joint1_motor", "actuator1", read_only=True),
                                 E("joint2_motor", "actuator2"))),))],
         interfaces=(["joint1/position", "joint2/position"],
                     ["joint1/position", "joint2/position"])),
    Case("sensor_only", urdf("valid_urdf_ros2_control_sensor_only"), [
        B("CameraWithIMU", "sensor", "ros2_control_demo_hardware/CameraWithIMUSensor",
          params=P(None, "2"), sensors=(C("sensor1", (), ("roll", "pitch", "yaw")),
                                        C("sensor2", (), ("image",))))],
         interfaces=(["sensor1/roll", "sensor1/pitch", "sensor1/yaw", "sensor2/image"], [])),
    Case("actuator_only", urdf("valid_urdf_ros2_control_actuator_only"),
         actuator_only(("velocity",))),
    Case("system_robot_with_gpio", urdf("valid_urdf_ros2_control_system_robot_with_gpio"), [
        rrbot("RRBotSystemWithGPIO", "ros2_control_demo_hardware/RRBotSystemWithGPIOHardware",
              gpios=(C("flange_analog_IOs", ("analog_output1",),
                       ("analog_output1", "analog_input1", "analog_input2")),
                     C("flange_vacuum", ("vacuum",), (Itf("vacuum", initial="1.0"),))))],
         interfaces=(["joint1/position", "joint2/position", "flange_analog_IOs/analog_output1",
                      "flange_analog_IOs/analog_input1", "flange_analog_IOs/analog_input2",
                      "flange_vacuum/vacuum"],
                     ["joint1/position", "joint2/position", "flange_analog_IOs/analog_output1",
                      "flange_vacuum/vacuum"])),
    Case("system_with_size_and_data_type",
         urdf("valid_urdf_ros2_control_system_robot_with_size_and_data_type"), [
             B("RRBotSystemWithSizeAndDataType", "system",
               "ros2_control_demo_hardware/RRBotSystemWithSizeAndDataType", params=P(),
               joints=(C("joint1", ("position",), ("position",)),), gpios=(FLANGE_IOS,),
               limits={"joint1": HEAD})],
         warnings=(CV_MAT,)),
    Case("system_with_bool_data_type_on_joint_sensor_and_gpio", urdf(
        "valid_urdf_ros2_control_system_robot_with_size_and_data_type_on_joint_sensor_and_gpio"), [
        B("RRBotSystemWithSizeAndDataType", "system",
          "ros2_control_demo_hardware/RRBotSystemWithSizeAndDataType", params=P(),
          joints=(C("joint1", ("position", Itf("enable", data_type="bool")),
                    ("position", Itf("status", data_type="bool"))),),
          sensors=(C("trigger", (Itf("safety", data_type="bool"),),
                     (Itf("safety", data_type="bool"),)),),
          gpios=(FLANGE_IOS,), limits={"joint1": HEAD})],
         warnings=(CV_MAT,)),
    # <limits enable="false"/> on an interface and on a joint
    Case("system_and_disabled_interfaces", urdf(
        "valid_urdf_ros2_control_system_robot_with_gpio_and_disabled_interface_limits"), [
        B("RRBotSystemWithGPIO", "system", "ros2_control_demo_hardware/RRBotSystemWithGPIOHardware",
          params=P(), joints=(
              DISABLED_JOINT1,
              C("joint2", (Itf("position", -1, 1, enable=False), Itf("velocity", enable=False),
                           Itf("effort", enable=False), Itf("acceleration", -0.3, 0.3, enable=False),
                           Itf("jerk", -2.0, 2.0, enable=False)), (Itf("position", enable=False),)),
              C("joint3", (Itf("acceleration", max=1.0),))),
          gpios=(FLANGE_IOS,),
          limits={"joint1": DISABLED_JOINT1_LIMITS, "joint2": None,
                  "joint3": L(-PI, PI, 0.2, 0.1, acceleration=1.0)},
          soft={"joint2": SOFT2})],  # limits off: the soft limits are not clamped
         warnings=(CV_MAT,)),
    Case("system_and_unavailable_interfaces",
         urdf("valid_urdf_ros2_control_system_robot_with_unavailable_interfaces"), [
             B("RRBotSystemWithGPIO", "system",
               "ros2_control_demo_hardware/RRBotSystemWithGPIOHardware", params=P(), joints=(
                   DISABLED_JOINT1,
                   C("joint2", (Itf("position", -1, 1, enable=False), Itf("velocity", enable=False),
                                Itf("effort", enable=False),
                                Itf("acceleration", -0.3, 0.3, enable=False),
                                Itf("jerk", enable=False)), (Itf("position", enable=False),)),
                   C("joint3", (Itf("acceleration", min=1.0), Itf("unavailable", -0.3, 0.3)))),
               limits={"joint1": DISABLED_JOINT1_LIMITS, "joint2": None,
                       "joint3": L(-PI, PI, 0.2, 0.1, deceleration=1.0)},
               soft={"joint2": SOFT2})],
         warnings=("joint3/unavailable",)),
    Case("urdf_system_continuous_missing_limits", urdf(
        "valid_urdf_ros2_control_system_robot_with_all_interfaces",
        head="urdf_head_continuous_missing_limits"),
         all_interfaces(L(-1, 1, 0.05, 0.2, acceleration=0.5, deceleration=0.5, jerk=5.0), None)),
    Case("urdf_system_continuous_with_limits", urdf(
        "valid_urdf_ros2_control_system_robot_with_all_interfaces",
        head="urdf_head_continuous_with_limits"),
         all_interfaces(L(-1, 1, 0.05, 0.1, acceleration=0.5, deceleration=0.5, jerk=5.0),
                        L(None, None, 0.2, 0.1))),
    Case("async_components", urdf("async_hardware_resources"), hardware_resources(
        async_params=(AsyncParams(30, "detached", [2, 4, 6], False), AsyncParams(),
                      AsyncParams(70, "synchronized", [1])))),
    Case("parameter_empty", urdf("valid_urdf_ros2_control_parameter_empty"), [
        B("2DOF_System_Robot_Position_Only", "system",
          "ros2_control_demo_hardware/2DOF_System_Hardware_Position_Only", params=P("", "2"),
          joints=(C("joint1", ("position",)),), limits={"joint1": HEAD})]),
    Case("gripper_mimic_true_valid_config", urdf(
        "gripper_hardware_resources_mimic_true_no_command_if", head="gripper_urdf_head"),
         gripper(), warnings=(NO_HARDWARE,)),
    Case("gripper_no_mimic_valid_config", urdf(
        "gripper_hardware_resources_no_command_if", head="gripper_urdf_head"),
         gripper(), warnings=(NO_HARDWARE,)),
    Case("gripper_mimic_false_valid_config", urdf(
        "gripper_hardware_resources_mimic_false_command_if", head="gripper_urdf_head"),
         gripper(("effort",), mimic=()), warnings=(NO_HARDWARE,)),
    Case("valid_rw_rate", urdf("hardware_resources_with_different_rw_rates"),
         hardware_resources(rw_rates=(50, 20, 25))),
    Case("urdf_with_disabled_limits", urdf("hardware_resources_with_disabled_limits"), [
        B("TestActuatorHardware", "actuator", "test_actuator", joints=(C("joint1", (
            Itf("position", enable=False), Itf("velocity", enable=False), Itf("effort", enable=False),
            Itf("max_velocity", enable=False)),
            (Itf("position", enable=False), Itf("velocity", enable=False))),), limits={"joint1": None}),
        B("TestSensorHardware", "sensor", "test_sensor", params=P(),
          sensors=(C("sensor1", (), ("velocity",)),)),
        B("TestSystemHardware", "system", "test_system", params=P(), joints=(
            C("joint2", (Itf("velocity", enable=False), Itf("max_acceleration", enable=False)),
              (Itf("position", enable=False), Itf("velocity", enable=False),
               Itf("acceleration", enable=False))),
            C("joint3", (Itf("position", enable=False), "velocity"),
              ("position", "velocity", "acceleration"))),
          gpios=(C("configuration", ("max_tcp_jerk",), ("max_tcp_jerk",)),),
          limits={"joint2": None, "joint3": L(None, None, 0.2, 0.1)}, soft={"joint2": SOFT2})]),
    Case("valid_sdf", ("diff_drive_robot_sdf",), [
        B("GazeboSimSystem", "system", "gz_ros2_control/GazeboSimSystem", joints=tuple(
            C(f"{side}_wheel_joint", (Itf("velocity", -10, 10),), ("velocity", "position"))
            for side in ("left", "right")),
          # SDF: ±inf bounds are none; the velocity limit is the interface's
          limits={f"{side}_wheel_joint": L(None, None, 10, None) for side in ("left", "right")})],
         note="SDF limits as deltoctl reads them; the parser test checks none"),
    # Beyond the parser test: the other snippets of components_urdfs.hpp, on urdf_head
    Case("voltage_sensor_only", urdf("valid_urdf_ros2_control_voltage_sensor_only"), [
        B("SingleJointVoltage", "sensor", "ros2_control_demo_hardware/SingleJointVoltageSensor",
          params=P(None, "2"), sensors=(C("sens1", (), ("voltage",)),))]),  # initial_value=
    Case("joint_voltage_sensor", urdf("valid_urdf_ros2_control_joint_voltage_sensor"), [
        B("SingleJointVoltage", "sensor", "ros2_control_demo_hardware/SingleJointVoltageSensor",
          params=P(None, "2"), joints=(C("joint1", (), ("position",)),),
          sensors=(C("sens1", (), ("voltage",)),), limits={"joint1": HEAD})]),
    Case("dummy_actuator_only", urdf("valid_urdf_ros2_control_dummy_actuator_only"),
         actuator_only(("position", "velocity"))),
    Case("dummy_system_robot", urdf("valid_urdf_ros2_control_dummy_system_robot"), [
        B("RRBotSystemWithGPIO", "system", "ros2_control_demo_hardware/RRBotSystemWithGPIOHardware",
          params=P(), joints=tuple(C(f"joint{n}", (VEL,), ("position", "velocity"))
                                   for n in (1, 2, 3)),
          limits={f"joint{n}": HEAD for n in (1, 2, 3)}, soft={"joint2": SOFT2})]),
    # named invalid upstream but read by component_parser: a joint without interfaces,
    # a <plugin> inside a joint (ignored)
    Case("component_missing_plugin_name",
         urdf("invalid_urdf_ros2_control_component_missing_plugin_name"), [
             B("2DOF_System_Robot_Position_Only", "system",
               "ros2_control_demo_hardware/2DOF_System_Hardware_Position_Only", params=P(),
               joints=(C("joint1", params={"min_position_value": "-1",
                                           "max_position_value": "1"}),),
               limits={"joint1": HEAD})],
         warnings=("no command or state interface",)),
    Case("component_plugin_name_empty",
         urdf("invalid_urdf_ros2_control_component_plugin_name_empty"), [
             B("2DOF_System_Robot_Position_Only", "system",
               "ros2_control_demo_hardware/2DOF_System_Hardware_Position_Only", params=P(),
               joints=(C("joint1", params={"min_position_value": "-1",
                                           "max_position_value": "1"}),),
               limits={"joint1": HEAD})],
         warnings=("ignores <plugin>", "no command or state interface")),
    # … and the whole descriptions of descriptions.hpp other ros2_control tests load
    # hardware_resources carries <transmission>s in its blocks; minimal_robot_transmissions
    # adds ROS 1 style ones under <robot>, which ros2_control does not read
    Case("minimal_robot_urdf", urdf("hardware_resources", "minimal_robot_transmissions"),
         hardware_resources(transmissions=True)),
    Case("minimal_robot_urdf_no_limits",
         urdf("hardware_resources", head="urdf_head_continuous_missing_limits"), [
             {**block, "limits": limits, "soft": {}} for block, limits in zip(
                 hardware_resources(transmissions=True), ({"joint1": None}, {}, {"joint2": None, "joint3": HEAD}))]),
    Case("diffbot_urdf", ("diffbot_urdf",), [
        *(B(f"TestActuatorHardware{side.title()}", "actuator", "test_actuator",
            joints=(C(f"wheel_{side}", ("velocity",), ("position", "velocity")),),
            limits={f"wheel_{side}": L(None, None, 1.0, 100)}) for side in ("left", "right")),
        B("TestIMUSensorHardware", "sensor", "test_hardware_components/TestIMUSensor",
          sensors=(C("base_imu", (), tuple(f"{q}.{axis}" for q, axes in (
              ("orientation", "xyzw"), ("angular_velocity", "xyz"),
              ("linear_acceleration", "xyz")) for axis in axes)),))]),
    Case("urdf_without_hardware_plugin", ("invalid_urdf_without_hardware_plugin",), [
        B("default", "system", "")], warnings=(NO_HARDWARE,),
         note="component_parser reads it; the controller manager then has no plugin to load"),
    Case("urdf_with_nonexistent_plugin", ("invalid_urdf_with_nonexistent_plugin",), [
        B("default", "system", "mock_components/NonExistentSystem")],
         note="component_parser reads it; only loading the plugin fails"),
]

INVALID = [
    Case("empty_string", ("inline_empty_string_throws_error",), words=("empty",)),
    Case("empty_urdf", ("inline_empty_urdf_throws_error",), words=("'ros2_control' tag",)),
    Case("string_robot_not_root", ("inline_string_robot_not_root_throws_error",),
         words=("XML",)),
    Case("invalid_child", urdf("invalid_urdf_ros2_control_invalid_child"),
         words=("invalid tag name", "hardwarert")),
    Case("missing_attribute", urdf("invalid_urdf_ros2_control_missing_attribute"),
         words=("no attribute 'name'", "ros2_control")),
    Case("parameter_missing_name", urdf("invalid_urdf_ros2_control_parameter_missing_name"),
         words=("parameter name", "2DOF_System_Robot_Position_Only")),
    Case("component_interface_type_empty",
         urdf("invalid_urdf_ros2_control_component_interface_type_empty"),
         words=("no attribute 'name'", "state_interface")),
    Case("revolute_missing_limits", urdf("valid_urdf_ros2_control_system_one_interface",
                                         head="urdf_head_revolute_missing_limits"),
         words=("joint1", "revolute", "<limit>")),
    Case("prismatic_missing_limits", urdf("valid_urdf_ros2_control_system_one_interface",
                                          head="urdf_head_prismatic_missing_limits"),
         words=("joint1", "prismatic", "<limit>")),
    Case("system_with_command_fixed_joint",
         urdf("invalid_urdf_ros2_control_system_with_command_fixed_joint"),
         words=("tool_joint", "fixed")),
    Case("async_invalid_thread_priority", urdf("inline_async_invalid_thread_priority"),
         words=("thread_priority", "-30")),
    Case("negative_size", urdf("invalid_urdf2_ros2_control_illegal_size"), words=("size", "-4")),
    Case("noninteger_size", urdf("invalid_urdf2_ros2_control_illegal_size2"),
         words=("size", "ILLEGAL")),
    Case("transmission_and_component_joint_mismatch",
         urdf("invalid_urdf2_hw_transmission_joint_mismatch"),
         words=("joint31415", "not available", "ActuatorModularJoint1")),
    # ros2_control finds joint2 missing from the block before it counts the joints
    Case("transmission_given_too_many_joints",
         urdf("invalid_urdf2_transmission_given_too_many_joints"),
         words=("transmission1", "joint2", "not available")),
    Case("negative_rw_rates", urdf("hardware_resources_with_negative_rw_rates",
                                   head="gripper_urdf_head"), words=("rw_rate", "-50")),
    Case("invalid_rw_rates", urdf("hardware_resources_invalid_with_text_in_rw_rates",
                                  head="gripper_urdf_head"), words=("rw_rate", "d 50")),
    Case("invalid_rw_rates_out_of_range", urdf(
        "hardware_resources_invalid_out_of_range_in_rw_rates", head="gripper_urdf_head"),
         words=("rw_rate", "out of range")),
    Case("gripper_mimic_with_unknown_joint", urdf(
        "gripper_hardware_resources_mimic_true_no_command_if",
        head="gripper_urdf_head_unknown_joint"),
         words=("mimic joint", "middle_finger_joint", "not found")),
    Case("gripper_mimic_true_without_mimic_info", urdf(
        "gripper_hardware_resources_mimic_true_no_command_if", head="gripper_urdf_head_no_mimic"),
         words=("left_finger_joint", "no mimic information")),
    Case("gripper_mimic_true_invalid_config", urdf(
        "gripper_hardware_resources_mimic_true_command_if", head="gripper_urdf_head"),
         words=("left_finger_joint", "cannot have command interfaces")),
    Case("urdf_two_root_links", urdf(
        "gripper_hardware_resources_mimic_true_no_command_if",
        head="gripper_urdf_head_invalid_two_root_links"), words=("two root links",)),
    Case("urdf_incomplete", urdf("gripper_hardware_resources_mimic_true_no_command_if",
                                 head="gripper_urdf_head_incomplete"),
         words=("left_finger_joint", "not found in the URDF")),
    Case("missing_hardware_plugin_tag_includes_component_name",
         ("inline_missing_hardware_plugin_tag_includes_component_name",),
         words=("MySpecificRobot", "<plugin>", "<hardware>")),
    Case("missing_joint_attribute_includes_joint_name",
         ("inline_missing_joint_attribute_includes_joint_name",),
         words=("name", "command_interface", "joint2")),
    Case("parameter_missing_name_includes_parent_context",
         ("inline_parameter_missing_name_includes_parent_context",),
         words=("joint1", "parameter name")),
    # beyond the parser test
    Case("urdf_no_geometry", ("invalid_urdf_no_geometry",), words=("no <link>",),
         note="urdfdom (ros2_control's URDF model) refuses a robot without links"),
    Case("duplicated_component", urdf("hardware_resources_duplicated_component"),
         words=("duplicate", "TestActuatorHardware"),
         note="component_parser reads it; ros2_control's resource manager refuses it"),
]


# -- what deltoctl loaded, in the same shape ------------------------------------------------------

def _interface_view(itf: Interface, comp: Component) -> dict[str, Any]:
    return Itf(itf.name, itf.min, itf.max, itf.initial_value, itf.params,
             itf.data_type or "double", itf.size or 1, itf.enable_limits and comp.enable_limits)


def _component_view(comp: Component) -> dict[str, Any]:
    return C(comp.name, tuple(_interface_view(i, comp) for i in comp.command_interfaces),
             tuple(_interface_view(i, comp) for i in comp.state_interfaces), comp.params)


def view(profile: Profile) -> list[dict[str, Any]]:
    blocks = []
    for hw in profile.hardware:
        index = {j.name: n for n, j in enumerate(hw.joints)}
        blocks.append(B(
            hw.name, hw.type, hw.plugin, group=hw.group, params=hw.params,
            joints=tuple(_component_view(c) for c in hw.joints),
            sensors=tuple(_component_view(c) for c in hw.sensors),
            gpios=tuple(_component_view(c) for c in hw.gpios),
            limits={j.name: j.limits for j in hw.joints},
            soft={j.name: j.soft_limits for j in hw.joints if j.soft_limits is not None},
            transmissions=tuple(hw.transmissions),
            mimic=tuple((index[j.name], index[j.mimic.joint], j.mimic.multiplier, j.mimic.offset)
                        for j in hw.joints if j.mimic is not None),
            rw_rate=hw.rw_rate, async_params=hw.async_params))
    return blocks


def _load(case: Case, tmp_path: Path) -> Path:
    path = tmp_path / f"{case.id}.urdf"
    path.write_text("".join((ASSETS / f"{part}.xml").read_text() for part in case.parts))
    return path


@pytest.mark.parametrize("case", VALID, ids=[c.id for c in VALID])
def test_valid_case_loads_as_ros2_control_reads_it(case: Case, tmp_path: Path) -> None:
    """Through the catalog, as every verb loads a profile."""
    _check_valid(case, load_profile(_load(case, tmp_path)))


@pytest.mark.parametrize("case", VALID, ids=[c.id for c in VALID])
def test_valid_case_urdf_loader(case: Case, tmp_path: Path) -> None:
    """The URDF loader and validation alone."""
    from deltoctl.profile.urdf_loader import load_urdf_profile
    from deltoctl.profile.validate import validate

    _check_valid(case, validate(load_urdf_profile(_load(case, tmp_path))))


def _check_valid(case: Case, profile: Profile) -> None:
    got = view(profile)
    assert [b["name"] for b in got] == [b["name"] for b in case.blocks]
    for have, want in zip(got, case.blocks):
        assert have == want, f"block {want['name']}"
    messages = [w.message for w in profile.warnings]
    assert len(messages) == len(case.warnings), messages
    for message, part in zip(messages, case.warnings):
        assert part in message
    if case.interfaces is not None:
        assert (profile.state_interfaces(), profile.command_interfaces()) == case.interfaces


@pytest.mark.parametrize("case", INVALID, ids=[c.id for c in INVALID])
def test_invalid_case_is_refused_naming_what_ros2_control_names(case: Case, tmp_path: Path,
                                                                cli) -> None:
    path = _load(case, tmp_path)
    result = cli("profile", "validate", str(path))
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output
    assert re.search(rf"{re.escape(str(path))}:\d+: ", result.stderr), result.stderr
    for word in case.words:
        assert word.lower() in result.stderr.lower(), (word, result.stderr)


def test_the_suite_covers_every_parser_test_case() -> None:
    """Every TEST_F of test_component_parser.cpp that parses a URDF has its case here (the
    locale one reads the actuator-only asset again; the description tests are the
    system_multi_joints_transmission, sensor_only and system_robot_with_gpio cases)."""
    ids = {c.id for c in VALID + INVALID}
    assert len(ids) == len(VALID) + len(INVALID)
    assert len(VALID) == 36 and len(INVALID) == 28


def test_strict_turns_warnings_into_errors(tmp_path: Path) -> None:
    from deltoctl.errors import ProfileError
    from deltoctl.profile.validate import validate

    case = next(c for c in VALID if c.id == "gripper_mimic_true_valid_config")
    profile = load_profile(_load(case, tmp_path))
    with pytest.raises(ProfileError, match=r"no <hardware>.*--strict"):
        validate(profile, strict=True)


def test_whitespace_before_the_xml_declaration_keeps_lines(tmp_path: Path, cli) -> None:
    """Most test assets (and launch-generated descriptions) start with a newline."""
    path = tmp_path / "lead.urdf"
    path.write_text("\n  \n" + (ASSETS / "urdf_head.xml").read_text().lstrip()
                    + (ASSETS / "invalid_urdf_ros2_control_invalid_child.xml").read_text()
                    + (ASSETS / "urdf_tail.xml").read_text())
    result = cli("profile", "validate", str(path))
    line = next(n for n, text in enumerate(path.read_text().splitlines(), 1)
                if "<hardwarert>" in text)
    assert f"{path}:{line}: invalid tag name <hardwarert>" in result.stderr


def test_empty_robot_is_reported_at_its_line(tmp_path: Path, cli) -> None:
    path = tmp_path / "empty.urdf"
    path.write_text('<?xml version="1.0"?>\n\n<robot name="r"/>\n')
    result = cli("profile", "validate", str(path))
    assert result.exit_code == 2
    assert f"{path}:3: no <ros2_control> block" in result.stderr


def test_profile_show_reports_soft_limits_apart(tmp_path: Path, cli) -> None:
    case = next(c for c in VALID if c.id == "system_one_interface")
    path = _load(case, tmp_path)
    table = cli("profile", "show", str(path))
    assert table.exit_code == 0, table.output
    assert "soft [-1, 0.5]" in table.stdout
    part = cli("profile", "show", str(path), "joint2")
    assert "soft limits [-1, 0.5] (k_position 10, k_velocity 20)" in part.stdout
    import json

    data = json.loads(cli("profile", "show", "--json", str(path)).stdout)["result"]
    assert data["soft_limits"]["RRBotSystemPositionOnly"]["joint2"] == {"lower": -1, "upper": 0.5, "k_position": 10,
                                             "k_velocity": 20}
    assert data["profile"]["ros2_control"][0]["joints"][0]["limits"] == {
        "lower": -1, "upper": 1, "velocity": 0.2, "effort": 0.1}


@pytest.mark.parametrize("case", VALID, ids=[c.id for c in VALID])
def test_merging_the_interface_limits_again_changes_nothing(case: Case, tmp_path: Path) -> None:
    """model.merge_interface_limits is idempotent on what the URDF loader gives, so the catalog
    may run it on every profile (the YAML form has no URDF loader to merge for it)."""
    from deltoctl.profile.model import merge_interface_limits
    from deltoctl.profile.urdf_loader import load_urdf_profile

    for joint in load_urdf_profile(_load(case, tmp_path)).joints():
        assert merge_interface_limits(joint.limits, joint) == joint.limits, joint.name
