"""Readable JSON: objects one key per line, short lists of numbers on one line."""

from __future__ import annotations

import json


def _flat(v) -> bool:
    return not isinstance(v, (dict, list)) or (isinstance(v, list) and all(_flat(x) and not isinstance(x, list)
                                                                            for x in v))


def dumps(obj, indent: int = 1, _level: int = 0) -> str:
    pad, inner = ' ' * (indent * _level), ' ' * (indent * (_level + 1))
    if isinstance(obj, dict):
        if not obj:
            return '{}'
        items = [f'{inner}{json.dumps(str(k))}: {dumps(v, indent, _level + 1)}' for k, v in obj.items()]
        return '{\n' + ',\n'.join(items) + '\n' + pad + '}'
    if isinstance(obj, list):
        if all(_flat(x) for x in obj):
            text = json.dumps(obj, separators=(', ', ': '))
            if len(text) <= 100 or all(not isinstance(x, list) for x in obj):
                return text
        items = [inner + dumps(v, indent, _level + 1) for v in obj]
        return '[\n' + ',\n'.join(items) + '\n' + pad + ']'
    return json.dumps(obj)
