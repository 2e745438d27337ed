"""
Print the README's parameter table from the parameter specs (one source for both).

    .venv/bin/python tools/param_table.py > /tmp/table.md

``test_params.py::test_readme_parameter_table_is_the_specs`` checks the README holds
exactly these rows.
"""

from hcloth_ros.node_params import ALL_PARAMS, ros_type
from hcloth_ros.params import allowed

HEADER = ('| name | type | default | allowed | runtime | meaning |\n'
          '| --- | --- | --- | --- | --- | --- |')


def row(spec):
    """Return the README row of one parameter."""
    runtime = 'no' if spec.read_only else 'yes'
    return (f'| `{spec.name}` | {ros_type(spec)} | `{spec.default!r}` | {allowed(spec)} | '
            f'{runtime} | {spec.description} |')


def table():
    """Return the whole table, header included."""
    return '\n'.join([HEADER] + [row(spec) for spec in ALL_PARAMS])


if __name__ == '__main__':
    print(table())
