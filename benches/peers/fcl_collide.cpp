// Times FCL 0.7's collide() (BVHModel<OBBd>, the OBB traversal) on the files frcd's
// `cargo bench -p frcd-benches --bench collide_export` writes (FRCD_COLLIDE_EXPORT=DIR).
// Per step: the fastest of RUNS passes (passes outer, steps inner, as frcd's obb bench does).
// Build (Debian: apt-get install libfcl-dev):
//   g++ -O3 -march=x86-64-v2 -I/usr/include/eigen3 fcl_collide.cpp -lfcl -o fcl_collide
#include <fcl/fcl.h>
#include <cstdio>
#include <chrono>
#include <vector>
#include <memory>
#include <algorithm>
typedef std::chrono::steady_clock clk;
typedef fcl::BVHModel<fcl::OBBd> Model;
static std::shared_ptr<Model> read_model(FILE* f) {
  int n; if (fscanf(f, "%d", &n) != 1) return nullptr;
  auto m = std::make_shared<Model>(); m->beginModel(n, 3 * n);
  for (int i = 0; i < n; i++) {
    double v[9]; for (int k = 0; k < 9; k++) if (fscanf(f, "%lf", &v[k]) != 1) return nullptr;
    m->addTriangle(fcl::Vector3d(v[0], v[1], v[2]), fcl::Vector3d(v[3], v[4], v[5]), fcl::Vector3d(v[6], v[7], v[8]));
  }
  m->endModel(); return m;
}
static bool read_pose(FILE* f, fcl::Transform3d& tf) {
  fcl::Matrix3d r; fcl::Vector3d t;
  for (int i = 0; i < 3; i++) for (int j = 0; j < 3; j++) if (fscanf(f, "%lf", &r(i, j)) != 1) return false;
  for (int k = 0; k < 3; k++) if (fscanf(f, "%lf", &t[k]) != 1) return false;
  tf.setIdentity(); tf.linear() = r; tf.translation() = t; return true;
}
static double median(std::vector<double> v) { if (v.empty()) return 0; std::sort(v.begin(), v.end()); return v[v.size() / 2]; }
int main(int argc, char** argv) {
  const int RUNS = 4;
  for (int a = 1; a < argc; a++) {
    FILE* f = fopen(argv[a], "r"); if (!f) { perror(argv[a]); return 1; }
    auto m1 = read_model(f); auto m2 = read_model(f);
    int n; if (!m1 || !m2 || fscanf(f, "%d", &n) != 1) { fprintf(stderr, "bad file %s\n", argv[a]); return 1; }
    std::vector<fcl::Transform3d> pa(n), pb(n); std::vector<int> touch(n), npairs(n);
    for (int i = 0; i < n; i++)
      if (!read_pose(f, pa[i]) || !read_pose(f, pb[i]) || fscanf(f, "%d %d", &touch[i], &npairs[i]) != 2) { fprintf(stderr, "bad step %d\n", i); return 1; }
    fclose(f);
    fcl::CollisionObjectd o1(m1), o2(m2);
    for (int all = 0; all < 2; all++) {
      fcl::CollisionRequestd req(all ? 100000000 : 1, false);
      std::vector<double> t(n, 1e300); std::vector<int> got(n);
      for (int run = 0; run < RUNS; run++) {
        for (int i = 0; i < n; i++) {
          o1.setTransform(pa[i]); o2.setTransform(pb[i]);
          fcl::CollisionResultd res;
          auto t0 = clk::now();
          fcl::collide(&o1, &o2, req, res);
          double e = std::chrono::duration<double>(clk::now() - t0).count();
          t[i] = std::min(t[i], e);
          got[i] = all ? (int)res.numContacts() : (int)res.isCollision();
        }
      }
      std::vector<double> dis, tou; double total = 0; int agree = 0;
      for (int i = 0; i < n; i++) {
        total += t[i]; (touch[i] ? tou : dis).push_back(t[i] * 1e6);
        agree += got[i] == (all ? npairs[i] : touch[i]);
      }
      printf("[fcl] %s %s: total ms %.2f | median us disjoint/touching %.1f/%.1f | steps %d agree with frcd %d\n",
             argv[a], all ? "all" : "first", total * 1e3, median(dis), median(tou), n, agree);
      fflush(stdout);
    }
  }
}
