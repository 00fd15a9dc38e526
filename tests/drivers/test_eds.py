"""Issue 21, acceptance D (first half): every node's EDS file loads with the ``canopen``
package's EDS importer and says what docs/canopen-plan.md says."""

from __future__ import annotations

import canopen
import pytest
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from drivers import canopen_frames as cf
from drivers import rig_nodes as rn

DEVICE_TYPES = {
    "relay": 0,
    "caging": cf.DEVICE_TYPE_401_DO,
    "torquer": cf.DEVICE_TYPE_401_AO,
    "command": cf.DEVICE_TYPE_401_AO,
    "table": 0,
}


def variables(od: canopen.ObjectDictionary) -> list[ODVariable]:
    out: list[ODVariable] = []
    for obj in od.values():
        if isinstance(obj, ODVariable):
            out.append(obj)
        else:
            assert isinstance(obj, ODArray | ODRecord)
            out.extend(obj.values())
    return out


@pytest.mark.parametrize("name", list(rn.NODES))
def test_each_eds_loads_and_has_the_cia301_objects(name):
    node_id = rn.NODES[name]
    od = canopen.import_od(str(cf.eds_path(name)), node_id)
    assert od[0x1000].default == DEVICE_TYPES[name]
    assert od[0x1018][2].default == rn.PRODUCT_CODES[name]  # product code
    assert od[0x1016][1].default >> 16 == cf.HOST_NODE_ID  # consumes the host's heartbeat
    assert od[0x1017].default == 100
    assert od[0x1200][1].default == 0x600 + node_id and od[0x1200][2].default == 0x580 + node_id
    for var in variables(od):  # a node serving its EDS answers every object
        assert var.default is not None, f"{name}: 0x{var.index:04x}:{var.subindex} has no default"


@pytest.mark.parametrize("name,outputs", [("torquer", 4), ("command", 6)])
def test_the_dac_nodes_are_cia401_analogue_outputs(name, outputs):
    od = canopen.import_od(str(cf.eds_path(name)), rn.NODES[name])
    for index in (0x6411, 0x6443, 0x6444, 0x6450, 0x2100):
        assert od[index][0].default == outputs, hex(index)
    assert all(
        od[0x6411][s].data_type == canopen.objectdictionary.INTEGER16 and od[0x6411][s].pdo_mappable
        for s in range(1, outputs + 1)
    )
    assert all(
        od[0x6450][s].default == cf.SI_VOLT and od[0x2100][s].default == 10_000_000
        for s in range(1, outputs + 1)
    )
    mapped = [
        od[0x1600 + p][s].default
        for p in range(2)
        if 0x1600 + p in od
        for s in range(1, od[0x1600 + p][0].default + 1)
    ]
    assert mapped == [0x64110010 | s << 8 for s in range(1, outputs + 1)]  # every output on an RPDO


def test_the_caging_node_is_cia401_digital_outputs():
    od = canopen.import_od(str(cf.eds_path("caging")), rn.NODES["caging"])
    assert (
        od[0x6200][1].data_type == canopen.objectdictionary.UNSIGNED8 and od[0x6200][1].pdo_mappable
    )
    assert od[0x6206][1].default == 0x0F and od[0x6207][1].default == 0


def test_the_relay_and_table_objects_are_manufacturer_specific():
    relay = canopen.import_od(str(cf.eds_path("relay")), rn.NODES["relay"])
    assert [relay[i].name for i in range(0x2000, 0x2007)] == [
        "Mode in force",
        "Mode switches (1 = hold, 2 = release)",
        "Selected mode",
        "Interlock reasons of the last refusal",
        "Status word",
        "Platform clamp (1 = clamped, motor drive open)",
        "Safe (write 1)",
    ]
    assert relay[0x2002].min == 1 and relay[0x2002].max == 6
    table = canopen.import_od(str(cf.eds_path("table")), rn.NODES["table"])
    assert table[0x2200].max == 90_000_000
