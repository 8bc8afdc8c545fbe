"""OpenSim ExternalLoads files (XML) and their data files (storage, .mot) written from a few
lines: one load ``push`` whose columns are ``f_v*`` (force), ``f_p*`` (point) and a torque's."""

from __future__ import annotations

from pathlib import Path

COLUMNS = ("f_vx", "f_vy", "f_vz", "f_px", "f_py", "f_pz", "f_tx", "f_ty", "f_tz")
MOT_COLUMNS = ("f_vx", "f_vy", "f_vz", "f_px", "f_py", "f_pz", "m_x", "m_y", "m_z")


def loads_xml(body: str = "shank", point_frame: str = "ground", datafile: str | None = "push.mot",
              torque: str = "f_t") -> str:
    """OpenSim's ExternalLoads with one force on ``body``, in ground's axes, its point in
    ``point_frame``'s; its columns f_v*, f_p* and ``torque``* (a free moment)."""
    data = "" if datafile is None else f"<datafile>{datafile}</datafile>"
    return ('<?xml version="1.0" encoding="UTF-8" ?>\n'
            '<OpenSimDocument Version="30000"><ExternalLoads name="push"><objects>'
            f'<ExternalForce name="push"><applied_to_body>{body}</applied_to_body>'
            "<force_expressed_in_body>ground</force_expressed_in_body>"
            f"<point_expressed_in_body>{point_frame}</point_expressed_in_body><force_identifier>f_v</force_identifier>"
            f"<point_identifier>f_p</point_identifier><torque_identifier>{torque}</torque_identifier></ExternalForce>"
            f"</objects>{data}</ExternalLoads></OpenSimDocument>\n")


def storage(t0: float = 0.0, t1: float = 1.0, columns=COLUMNS, value: str = "2.0") -> str:
    """A storage file of 11 rows from t0 to t1 (s), every column ``value``."""
    rows = ["push", "version=1", "endheader", "\t".join(("time",) + tuple(columns))]
    rows += ["\t".join([repr(t0 + (t1 - t0) * k / 10)] + [value] * len(columns)) for k in range(11)]
    return "\n".join(rows) + "\n"


def write(folder: Path, xml: str | None = None, data: str | None = None, name: str = "push.xml",
          data_name: str = "push.mot") -> Path:
    """``folder/name`` (the loads, :func:`loads_xml` by default) and ``folder/data_name`` (its data,
    :func:`storage` by default); the path of the loads file."""
    (folder / name).write_text(loads_xml() if xml is None else xml)
    (folder / data_name).write_text(storage() if data is None else data)
    return folder / name


def push_files(folder: Path, t, force, point, moment, datafile: str = "push.mot") -> Path:
    """``folder/push.xml``: a push on the shank, its force (N) and point (m) in ground's axes and a
    free moment (N m), the same at every time of ``t`` (s); its data in ``folder/datafile`` (named
    relative to the XML, as OpenSim's examples do) as OpenSim writes a .mot."""
    values = tuple(force) + tuple(point) + tuple(moment)
    rows = "\n".join("\t".join(f"{v:g}" for v in (ti,) + values) for ti in t)
    data = folder / datafile
    data.parent.mkdir(parents=True, exist_ok=True)
    data.write_text(f"push\nversion=1\nnRows={len(t)}\nnColumns=10\ninDegrees=yes\nendheader\n"
                    + "\t".join(("time",) + MOT_COLUMNS) + "\n" + rows + "\n")
    xml = folder / "push.xml"
    xml.write_text(loads_xml(datafile=datafile, torque="m_"))
    return xml
