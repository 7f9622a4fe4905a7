"""ROS 2 command-line arguments and name resolution (node name, namespace, remapping).

Nodes accept exactly what ``ros2 run`` passes: ``--ros-args -r __node:=name -r __ns:=/ns
-r from:=to --params-file f.yaml -p name:=value --log-level info``, so the same command line
works on the rclpy and the Cyclone DDS backend and launch files need no special case.
"""

from dataclasses import dataclass, field


class ArgumentError(ValueError):
    """A malformed ``--ros-args`` section."""


@dataclass
class RosArgs:
    node_name: str | None = None
    namespace: str | None = None
    param_files: list[str] = field(default_factory=list)
    overrides: list[tuple[str, str]] = field(default_factory=list)
    remaps: dict[str, str] = field(default_factory=dict)
    log_level: str | None = None
    user_args: list[str] = field(default_factory=list)


def parse_ros_args(argv: list[str]) -> RosArgs:
    """Split ``argv`` (without the program name) into ROS arguments and the node's own."""
    result = RosArgs()
    i = 0
    in_ros = False
    while i < len(argv):
        arg = argv[i]
        if arg == "--ros-args":
            in_ros = True
        elif arg == "--" and in_ros:
            in_ros = False
        elif not in_ros:
            result.user_args.append(arg)
        elif arg in ("-r", "--remap", "-p", "--param", "--params-file", "--log-level"):
            if i + 1 >= len(argv):
                raise ArgumentError(f"{arg} needs a value")
            value = argv[i + 1]
            i += 1
            if arg == "--params-file":
                result.param_files.append(value)
            elif arg == "--log-level":
                result.log_level = value.split(":=")[-1]
            else:
                if ":=" not in value:
                    raise ArgumentError(f"{arg} {value!r}: expected name:=value")
                key, val = value.split(":=", 1)
                if arg in ("-p", "--param"):
                    result.overrides.append((key, val))
                elif key in {"__node", "__name"}:
                    result.node_name = val
                elif key == "__ns":
                    result.namespace = val
                else:
                    result.remaps[key] = val
        elif arg in ("--enclave", "-e"):
            i += 1  # accepted for compatibility, no security here
        else:
            raise ArgumentError(f"unknown ROS argument {arg!r}")
        i += 1
    return result


def normalize_namespace(namespace: str | None) -> str:
    ns = "/" + (namespace or "").strip("/")
    return ns if ns != "/" else "/"


def resolve_name(name: str, namespace: str, node_name: str, remaps: dict[str, str]) -> str:
    """Fully qualified topic name after ROS 2 expansion (``~``, relative) and remapping."""
    ns = normalize_namespace(namespace)
    prefix = "" if ns == "/" else ns
    if name.startswith("~"):
        full = f"{prefix}/{node_name}{name[1:]}"
    elif name.startswith("/"):
        full = name
    else:
        full = f"{prefix}/{name}"
    for key in (name, full):
        if key in remaps:
            target = remaps[key]
            return target if target.startswith("/") else f"{prefix}/{target}"
    return full
