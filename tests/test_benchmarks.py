"""The benchmarks (run on demand, never by CI) still import against the package: a renamed or removed
name they use fails here rather than on the day someone runs them."""
import subprocess
import sys
import textwrap

from .conftest import BENCHMARKS

# each module is executed up to its ``if __name__ == "__main__"`` guard, in a process of its own: some set
# thread variables at import, which must not reach the test process
IMPORT_ALL = textwrap.dedent("""
    import importlib.util, sys, traceback
    failed = []
    sys.path.insert(0, sys.argv[1])   # as running one: its folder first (some import their neighbours)
    for path in sys.argv[2:]:
        spec = importlib.util.spec_from_file_location("benchmark_" + path.rsplit("/", 1)[-1][:-3], path)
        module = sys.modules[spec.name] = importlib.util.module_from_spec(spec)   # as an import registers it
        try:
            spec.loader.exec_module(module)
        except Exception:
            failed.append(path + ": " + traceback.format_exc().strip().splitlines()[-1])
    print("\\n".join(failed))
    sys.exit(1 if failed else 0)
""")


def test_every_benchmark_imports(tmp_path):
    scripts = sorted(str(p) for p in BENCHMARKS.glob("*.py"))
    assert len(scripts) >= 20
    proc = subprocess.run([sys.executable, "-c", IMPORT_ALL, str(BENCHMARKS), *scripts], capture_output=True, text=True,
                          timeout=600, cwd=tmp_path)
    assert proc.returncode == 0, proc.stdout + proc.stderr[-2000:]
