"""Reading generated ROS 2 interfaces as upstream defines them, for the tests that compare ours
(tests/msgs/test_*_msgs.py) with upstream's fields, constants and RIHS01 type hashes."""

from __future__ import annotations

import json
import os


def rosidl_constants(cls) -> dict:
    """The constants rosidl generated for cls (they live on its metaclass), name -> value."""
    return {name: getattr(cls, name) for name in vars(type(cls)) if name.isupper() and not name.startswith('_')}


def installed_type_hashes(package: str, interface: str) -> dict[str, str]:
    """type name -> RIHS01 hash string, from the type description rosidl installed for
    `interface` ('msg/Name', 'action/Name', ...) of `package`."""
    from ament_index_python.packages import get_package_share_directory
    with open(os.path.join(get_package_share_directory(package), interface + '.json')) as f:
        return {h['type_name']: h['hash_string'] for h in json.load(f)['type_hashes']}
