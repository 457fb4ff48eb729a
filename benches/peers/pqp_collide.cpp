// Times PQP 1.3's PQP_Collide on the files `cargo bench -p frcd-benches --bench collide_export`
// writes (FRCD_COLLIDE_EXPORT=DIR), so PQP runs exactly the steps frcd's `obb` bench times.
// PQP is not part of frcd: get PQP 1.3 yourself, then, with its sources in $PQP:
//   g++ -O3 -march=x86-64-v2 -I$PQP pqp_collide.cpp $PQP/{PQP,Build,BV,TriDist}.cpp -o pqp_collide
//   ./pqp_collide DIR/*.txt
// Per step: the fastest of RUNS passes (passes outer, steps inner, as frcd's obb bench does),
// then totals and medians of disjoint/touching steps (split by frcd's exported answer).
// PQP_STEPS=DIR also writes each step (index, touching, µs, OBB tests, triangle tests) to
// DIR/<file>.<first|all>, to join with the obb bench's FRCD_BENCH_STEPS files.
#include "PQP.h"
#include <cstdio>
#include <chrono>
#include <vector>
#include <algorithm>
#include <cstdlib>
#include <string>
typedef std::chrono::steady_clock clk;
static PQP_Model* read_model(FILE* f) {
  int n; if (fscanf(f, "%d", &n) != 1) return 0;
  PQP_Model* m = new PQP_Model; m->BeginModel(n);
  for (int i = 0; i < n; i++) {
    double v[9]; for (int k = 0; k < 9; k++) if (fscanf(f, "%lf", &v[k]) != 1) return 0;
    m->AddTri(v, v + 3, v + 6, i);
  }
  m->EndModel(); return m;
}
struct P { double R[3][3]; double T[3]; };
static bool read_pose(FILE* f, P& p) {
  for (int r = 0; r < 3; r++) for (int c = 0; c < 3; c++) if (fscanf(f, "%lf", &p.R[r][c]) != 1) return false;
  for (int k = 0; k < 3; k++) if (fscanf(f, "%lf", &p.T[k]) != 1) return false;
  return true;
}
static double median(std::vector<double> v) { if (v.empty()) return 0; std::sort(v.begin(), v.end()); return v[v.size()/2]; }
int main(int argc, char** argv) {
  const int RUNS = 4;
  for (int a = 1; a < argc; a++) {
    FILE* f = fopen(argv[a], "r"); if (!f) { perror(argv[a]); return 1; }
    PQP_Model* m1 = read_model(f); PQP_Model* m2 = read_model(f);
    int n; if (!m1 || !m2 || fscanf(f, "%d", &n) != 1) { fprintf(stderr, "bad file %s\n", argv[a]); return 1; }
    std::vector<P> pa(n), pb(n); std::vector<int> touch(n), npairs(n);
    for (int i = 0; i < n; i++) {
      if (!read_pose(f, pa[i]) || !read_pose(f, pb[i]) || fscanf(f, "%d %d", &touch[i], &npairs[i]) != 2) { fprintf(stderr, "bad step %d\n", i); return 1; }
    }
    fclose(f);
    for (int flag : {PQP_FIRST_CONTACT, PQP_ALL_CONTACTS}) {
      std::vector<double> t(n, 1e300); std::vector<int> got(n), bvs(n), tris(n); double bv = 0, tri = 0;
      for (int run = 0; run < RUNS; run++) {
        for (int i = 0; i < n; i++) {
          PQP_CollideResult res;
          auto t0 = clk::now();
          PQP_Collide(&res, pa[i].R, pa[i].T, m1, pb[i].R, pb[i].T, m2, flag);
          double e = std::chrono::duration<double>(clk::now() - t0).count();
          t[i] = std::min(t[i], e);
          got[i] = flag == PQP_FIRST_CONTACT ? res.Colliding() : res.NumPairs();
          if (run == 0) { bv += res.NumBVTests(); tri += res.NumTriTests(); bvs[i] = res.NumBVTests(); tris[i] = res.NumTriTests(); }
        }
      }
      std::vector<double> dis, tou; double total = 0; int agree = 0;
      // PQP_STEPS=DIR: per-step times and work, one line per step, to compare step by step.
      if (const char* dir = getenv("PQP_STEPS")) {
        std::string name = std::string(argv[a]);
        name = std::string(dir) + "/" + name.substr(name.rfind('/') + 1) + (flag == PQP_FIRST_CONTACT ? ".first" : ".all");
        if (FILE* o = fopen(name.c_str(), "w")) {
          for (int i = 0; i < n; i++) fprintf(o, "%d %d %.3f %d %d\n", i, touch[i], t[i] * 1e6, bvs[i], tris[i]);
          fclose(o);
        } else {
          perror(name.c_str());
        }
      }
      for (int i = 0; i < n; i++) {
        total += t[i];
        (touch[i] ? tou : dis).push_back(t[i] * 1e6);
        int want = flag == PQP_FIRST_CONTACT ? touch[i] : npairs[i];
        agree += (got[i] == want);
      }
      printf("[pqp] %s %s: total ms %.2f | median us disjoint/touching %.1f/%.1f | steps %d agree with frcd %d | bv %.0f tri %.0f per query\n",
             argv[a], flag == PQP_FIRST_CONTACT ? "first" : "all", total * 1e3, median(dis), median(tou), n, agree, bv / n, tri / n);
      fflush(stdout);
    }
  }
}
