"""Looking at a plan: the offline HTML report of ``isf show`` and the mesh scene of ``isf export``.

Modules: ``plan_file`` (a plan file read back with its gripper and object),
``gripper_meshes`` (the gripper's link meshes posed by yourdfpy), ``report`` (the HTML page),
``scene_export`` (the mesh scene), ``dependencies`` (the check that plotly and yourdfpy,
dependencies of isf, import).
"""

from .dependencies import VIEWER_PACKAGES, require_viewer
from .gripper_meshes import GEOMETRIES, GripperMeshes, MeshPart
from .plan_file import PlanFile, PlanSources, SourceOptions, load_sources, open_plan
from .report import ReportSummary, report_data, report_html, write_report
from .scene_export import export_grasp, grasp_scene

__all__ = [
    "GEOMETRIES",
    "GripperMeshes",
    "MeshPart",
    "PlanFile",
    "PlanSources",
    "ReportSummary",
    "SourceOptions",
    "VIEWER_PACKAGES",
    "export_grasp",
    "grasp_scene",
    "load_sources",
    "open_plan",
    "report_data",
    "report_html",
    "require_viewer",
    "write_report",
]
