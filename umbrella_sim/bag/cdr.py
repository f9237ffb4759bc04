# Copyright 2026 umbrella_sim developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
ROS 2 messages as a recording stores them: their type names, definitions and exact CDR bytes.

``message_definition`` gives the ros2msg schema of a type (the .msg text with its
dependencies, as rosbag2 writes it); ``cdr_bytes`` the serialized message trimmed to its exact
CDR size with zeroed padding (rclpy may return a few bytes more, which rosbags refuses, and
leaves whatever its buffer held in the alignment gaps); ``qos_profiles`` the offered QoS profile
and ``type_description_hash`` the type's RIHS01 hash as rosbag2 (Jazzy) writes them.
"""
from __future__ import annotations

import os
import sys

from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
import yaml


DELIMITER = '=' * 80


_PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
               'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'}


_INFINITE = {'sec': 9223372036, 'nsec': 854775807}


# ------------------------------------------------------------------ type metadata
def type_name(msg_or_type) -> str:
    """'sensor_msgs/msg/JointState' for a message class or instance."""
    cls = msg_or_type if isinstance(msg_or_type, type) else type(msg_or_type)
    pkg = cls.__module__.split('.')[0]
    return f'{pkg}/msg/{cls.__name__}'


def _share_dirs() -> list[str]:
    dirs = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    dirs.append(sys.prefix)
    return [os.path.join(d, 'share') for d in dirs]


def _msg_text(full_name: str) -> str:
    pkg, _, name = full_name.split('/')
    for share in _share_dirs():
        path = os.path.join(share, pkg, 'msg', name + '.msg')
        if os.path.isfile(path):
            with open(path, encoding='utf-8') as fh:
                return fh.read()
    raise FileNotFoundError(f'message definition {full_name}.msg not found under '
                            "AMENT_PREFIX_PATH or the interpreter's share/")


def _dependencies(pkg: str, text: str) -> list[str]:
    """Message types used by the fields of a .msg text (constants are always primitive)."""
    deps = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        base = line.split()[0].split('[', 1)[0].split('<=', 1)[0]
        if base in _PRIMITIVES:
            continue
        p, n = (base.split('/')[0], base.split('/')[-1]) if '/' in base else (pkg, base)
        deps.append(f'{p}/msg/{n}')
    return deps


def message_definition(full_name: str) -> str:
    """
    Return the ros2msg 'complete message definition'.

    The type's .msg text, then every dependency
    after a line of 80 '=' and 'MSG: pkg/msg/Type' (rosbag2 docs/message_definition_encoding).
    """
    order: list[str] = []
    texts: dict[str, str] = {}

    def visit(name: str) -> None:
        if name in texts:
            return
        texts[name] = _msg_text(name)
        order.append(name)
        for dep in _dependencies(name.split('/')[0], texts[name]):
            visit(dep)

    visit(full_name)
    parts = [texts[order[0]].rstrip('\n')]
    for name in order[1:]:
        parts.append(f'{DELIMITER}\nMSG: {name}\n{texts[name].rstrip(chr(10))}')
    return '\n'.join(parts) + '\n'


#: the rosbag2 metadata version written: Jazzy's (9: offered_qos_profiles as a list with
#: the policies' names, each topic's RIHS01 type_description_hash)
BAG_FORMAT_VERSION = 9


def qos_profiles(qos: QoSProfile) -> list[dict]:
    """Return offered_qos_profiles as rosbag2 (metadata version 9) writes them."""
    return [{
        'history': qos.history.name.lower(), 'depth': int(qos.depth),
        'reliability': qos.reliability.name.lower(),
        'durability': qos.durability.name.lower(),
        'deadline': dict(_INFINITE), 'lifespan': dict(_INFINITE),
        'liveliness': qos.liveliness.name.lower(),
        'liveliness_lease_duration': dict(_INFINITE),
        'avoid_ros_namespace_conventions': False,
    }]


def qos_yaml(qos: QoSProfile) -> str:
    """Return offered_qos_profiles as a YAML string, as rosbag2 puts it on an MCAP channel."""
    return yaml.safe_dump(qos_profiles(qos), sort_keys=False).rstrip('\n')


def type_description_hash(full_name: str) -> str:
    """
    Return a message type's RIHS01 type description hash ('RIHS01_<64 hex>').

    As rosidl generated it: the interface package ships it in share/<pkg>/msg/<Type>.json
    beside the .msg; '' where that file is missing (an interface built before Iron).
    """
    import json

    pkg, _, name = full_name.split('/')
    for share in _share_dirs():
        path = os.path.join(share, pkg, 'msg', name + '.json')
        try:
            with open(path, encoding='utf-8') as fh:
                hashes = json.load(fh).get('type_hashes', [])
        except (OSError, ValueError):
            continue
        for entry in hashes:
            if entry.get('type_name') == full_name:
                return str(entry.get('hash_string', ''))
    return ''


# --------------------------------------------------------------- exact CDR size
_SIZES = {'boolean': 1, 'octet': 1, 'char': 1, 'uint8': 1, 'int8': 1, 'int16': 2, 'uint16': 2,
          'int32': 4, 'uint32': 4, 'float': 4, 'int64': 8, 'uint64': 8, 'double': 8,
          'long double': 16, 'wchar': 2}


def _align(pos: int, n: int, pads: list | None = None) -> int:
    """Return pos aligned to n, noting the gap in pads (CDR padding) if any."""
    end = (pos + n - 1) // n * n
    if pads is not None and end > pos:
        pads.append((pos, end))
    return end


#: message class -> its fields' size functions (built once per type: the walk runs for every
#: recorded message, so the type strings are parsed once, not per message)
_PLANS: dict = {}


def _cdr_end(msg, pos: int, pads: list | None = None) -> int:
    """Return where msg's CDR ends from pos; pads: collects its alignment gaps (start, end)."""
    plan = _PLANS.get(type(msg))
    if plan is None:
        plan = _PLANS[type(msg)] = [(field, _field_size(ftype)) for field, ftype
                                    in msg.get_fields_and_field_types().items()]
    for field, size in plan:
        pos = size(getattr(msg, field), pos, pads)
    return pos


def _field_size(ftype: str):
    """Return size(value, pos, pads) -> end position of one field of IDL type ftype."""
    if ftype.startswith('sequence<'):
        items = _items_size(ftype[len('sequence<'):-1].rsplit(',', 1)[0].strip())
        return lambda value, pos, pads: items(value, _align(pos, 4, pads) + 4, pads)
    if ftype.endswith(']'):
        return _items_size(ftype[:ftype.index('[')])
    items = _items_size(ftype)
    return lambda value, pos, pads: items((value,), pos, pads)


def _items_size(ftype: str):
    """Return size(values, pos, pads) -> end position of consecutive items of IDL type ftype."""
    if ftype.startswith('wstring'):
        def size(values, pos, pads):
            for v in values:
                pos = _align(pos, 4, pads) + 4 + 4 * (len(v) + 1)
            return pos
        return size
    if ftype.startswith('string'):
        def size(values, pos, pads):
            for v in values:
                pos = _align(pos, 4, pads) + 4 + len(v.encode('utf-8')) + 1
            return pos
        return size
    n = _SIZES.get(ftype)
    if n is not None:
        def size(values, pos, pads):
            k = len(values)
            return _align(pos, n, pads) + n * k if k else pos
        return size

    def size(values, pos, pads):                    # nested messages
        for v in values:
            pos = _cdr_end(v, pos, pads)
        return pos
    return size


def cdr_bytes(msg, data: bytes | None = None) -> bytes:
    """
    Serialise to CDR, trimmed to the exact size, with zero padding.

    rclpy may return a few padding bytes more, which rosbags rejects; ros2 bag record writes
    the exact size.  The alignment gaps are set to 0: the serializer leaves whatever its
    buffer held there, so the same message would serialize to different bytes from one
    process to the next, and a recording would depend on the process that made it.  data:
    msg already serialized, to serialize once.
    """
    if data is None:
        data = serialize_message(msg)
    pads: list = []
    size = 4 + _cdr_end(msg, 0, pads)           # 4-byte encapsulation header
    if size > len(data):
        raise RuntimeError(f'CDR size walk overran the payload for {type_name(msg)}')
    if not pads:
        return data[:size]
    out = bytearray(data[:size])
    for start, end in pads:                     # positions after the 4-byte header
        out[4 + start:4 + end] = bytes(end - start)
    return bytes(out)
