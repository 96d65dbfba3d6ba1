"""Every GLSL program, as the loader assembles it, passes Khronos' reference compiler.

The renderer's tests only compile the shaders on the driver they run on, and drivers differ in
what they accept (llvmpipe is lenient about some things that NVIDIA or Apple reject).
``glslangValidator`` (Debian/Ubuntu package ``glslang-tools``) checks the sources against the
GLSL specification itself, each stage alone and the two stages linked, so a program that only
compiles by a driver's grace is caught here.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from clothsim.render.programs import LOOKS, read_source
from clothsim.resources import data_dir

VALIDATOR = "glslangValidator"
SUFFIX = {"vertex": ".vert", "fragment": ".frag"}  # glslangValidator picks the stage by suffix


def _validator() -> str:
    path = shutil.which(VALIDATOR)
    if path is None:
        pytest.skip(f"{VALIDATOR} is not installed (Debian/Ubuntu: apt-get install glslang-tools); "
                    "the GLSL sources were not checked")
    return path


def validate(*stages: tuple[str, str]) -> subprocess.CompletedProcess:
    """Run the validator over ``(stage, source)`` pairs; with more than one, the stages are also
    linked, which checks that each fragment input matches a vertex output."""
    exe = _validator()
    with tempfile.TemporaryDirectory(prefix="clothsim-glsl-") as tmp:
        files = []
        for n, (stage, source) in enumerate(stages):
            path = Path(tmp) / f"s{n}{SUFFIX[stage]}"
            path.write_text(source, encoding="utf-8")
            files.append(str(path))
        link = ["-l"] if len(files) > 1 else []
        return subprocess.run([exe, *link, *files], capture_output=True, text=True, timeout=60)


def _check(done: subprocess.CompletedProcess, what: str) -> None:
    assert done.returncode == 0, f"{what}: {VALIDATOR} exit {done.returncode}\n{done.stdout}{done.stderr}"


@pytest.mark.parametrize("look", sorted(LOOKS))
def test_program_is_valid_glsl(look):
    vert_name, frag_name = LOOKS[look]
    vert, frag = read_source(vert_name), read_source(frag_name)
    assert "#include" not in vert + frag  # the validator must see what the driver gets
    _check(validate(("vertex", vert)), f"{look}: {vert_name}")
    _check(validate(("fragment", frag)), f"{look}: {frag_name}")
    _check(validate(("vertex", vert), ("fragment", frag)), f"{look}: {vert_name} + {frag_name} linked")


@pytest.mark.parametrize("vertex", sorted({vert for vert, _ in LOOKS.values()} - {"wireframe.vert", "channels.vert"}))
def test_id_pass_fragment_stage_is_valid_glsl_with_each_surface_vertex_stage(vertex):
    # render/seen.py draws a look's own vertex stage with ids.frag
    frag = read_source("ids.frag")
    _check(validate(("fragment", frag)), "ids.frag")
    _check(validate(("vertex", read_source(vertex)), ("fragment", frag)), f"{vertex} + ids.frag linked")


def test_validator_rejects_broken_sources():
    """The helper above reports failures: a syntax error, a type error, an unspliced include and a
    stage mismatch each make the validator fail."""
    vert, frag = read_source("mesh.vert"), read_source("phong.frag")
    assert validate(("vertex", vert), ("fragment", frag)).returncode == 0
    missing_semicolon = frag.replace("out_color = vec4(linear_to_srgb(c), 1.0);",
                                     "out_color = vec4(linear_to_srgb(c), 1.0)")
    wrong_type = frag.replace("out_color = vec4(linear_to_srgb(c), 1.0);", "out_color = linear_to_srgb(c);")
    unspliced = (data_dir("glsl") / "phong.frag").read_text(encoding="utf-8")
    mismatched = frag.replace("in vec3 v_normal;", "in vec4 v_normal;").replace(
        "facing_normal(v_normal)", "facing_normal(v_normal.xyz)")
    for broken in (missing_semicolon, wrong_type, mismatched):
        assert broken != frag
    assert '#include "common.glsl"' in unspliced
    for name, stages in (("missing semicolon", [("fragment", missing_semicolon)]),
                         ("vec3 assigned to vec4", [("fragment", wrong_type)]),
                         ("#include not spliced", [("fragment", unspliced)]),
                         ("vertex/fragment type mismatch", [("vertex", vert), ("fragment", mismatched)])):
        done = validate(*stages)
        assert done.returncode != 0, f"{name}: accepted\n{done.stdout}"
        assert "ERROR" in done.stdout + done.stderr, name
