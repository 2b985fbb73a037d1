/* An outside C program using an installed rkmpm (scripts/test-install.sh builds it with CMake and
 * with pkg-config, against librkmpm.a and librkmpm.so). A 3 x 3 block of particles in free fall
 * with a uniform initial velocity, on a 2D grid with free faces: every particle must keep the
 * velocity v0 + g t and move by the sum of dt * v over the steps (the grid reproduces a uniform
 * field exactly). Exits non-zero on any failure. */
#include <rkmpm.h>

#include <math.h>
#include <stdint.h>
#include <stdio.h>

#define CHECK(call)                                                                  \
  do {                                                                               \
    enum RkmpmStatus status_ = (call);                                               \
    if (status_ != RKMPM_OK) {                                                       \
      char message_[512];                                                            \
      rkmpm_last_error_message(message_, sizeof message_);                           \
      fprintf(stderr, "FAIL %s: %s: %s\n", #call, rkmpm_status_str(status_), message_); \
      return 1;                                                                      \
    }                                                                                \
  } while (0)

#define N 9
#define STEPS 5

int main(void) {
  if (rkmpm_abi_version() != RKMPM_ABI_VERSION) {
    fprintf(stderr, "FAIL: library ABI %u, header ABI %d\n", rkmpm_abi_version(), RKMPM_ABI_VERSION);
    return 1;
  }
  const double origin[2] = {0.0, 0.0};
  const size_t cells[2] = {16, 16};
  const double h = 1.0 / 16.0;
  const double gravity[2] = {0.0, -9.81};
  const double v0[2] = {0.5, 0.25};
  double x[2 * N], vol[N], v[2 * N], expected[2 * N], out[2 * N];
  for (int p = 0; p < N; p++) {
    x[2 * p] = 0.5 + (p % 3 - 1) * 0.5 * h;
    x[2 * p + 1] = 0.5 + (p / 3 - 1) * 0.5 * h;
    vol[p] = 0.25 * h * h;
    v[2 * p] = v0[0];
    v[2 * p + 1] = v0[1];
    expected[2 * p] = x[2 * p];
    expected[2 * p + 1] = x[2 * p + 1];
  }

  RkmpmSim *sim = NULL;
  uint32_t material = 0;
  CHECK(rkmpm_sim_new(2, origin, cells, h, &sim));
  CHECK(rkmpm_sim_set_gravity(sim, gravity));
  CHECK(rkmpm_sim_add_material_linear_elastic(sim, 1000.0, 1.0e6, 0.3, &material));
  CHECK(rkmpm_sim_add_particles(sim, material, N, x, vol, v));

  double t = 0.0;
  for (int s = 0; s < STEPS; s++) {
    double dt = 0.0;
    CHECK(rkmpm_sim_stable_dt(sim, 0.5, &dt));
    CHECK(rkmpm_sim_step(sim, dt));
    t += dt;
    for (int p = 0; p < N; p++) {
      expected[2 * p] += dt * (v0[0] + gravity[0] * t);
      expected[2 * p + 1] += dt * (v0[1] + gravity[1] * t);
    }
  }

  uint64_t steps = 0;
  double time = 0.0;
  CHECK(rkmpm_sim_step_count(sim, &steps));
  CHECK(rkmpm_sim_time(sim, &time));
  CHECK(rkmpm_sim_get_particles(sim, RKMPM_FIELD_POSITION, out, 2 * N));
  int failed = 0;
  if (steps != STEPS || rkmpm_sim_particle_count(sim) != N || fabs(time - t) > 1e-15) {
    fprintf(stderr, "FAIL: %llu steps, %zu particles, time %g (expected %d, %d, %g)\n",
            (unsigned long long)steps, rkmpm_sim_particle_count(sim), time, STEPS, N, t);
    failed = 1;
  }
  double worst = 0.0;
  for (int i = 0; i < 2 * N; i++) {
    double e = fabs(out[i] - expected[i]);
    if (!(e <= 1e-12)) failed = 1;
    if (e > worst || e != e) worst = e;
  }
  CHECK(rkmpm_sim_get_particles(sim, RKMPM_FIELD_VELOCITY, out, 2 * N));
  for (int p = 0; p < N; p++) {
    for (int d = 0; d < 2; d++) {
      double e = fabs(out[2 * p + d] - (v0[d] + gravity[d] * t));
      if (!(e <= 1e-10)) failed = 1;
    }
  }
  rkmpm_sim_free(sim);
  printf("rkmpm %s (ABI %u): %llu steps to t = %.6g s, particle 0 at (%.9f, %.9f), worst position error %.2g%s\n",
         rkmpm_version(), rkmpm_abi_version(), (unsigned long long)steps, t, expected[0], expected[1],
         worst, failed ? ": FAIL" : "");
  return failed;
}
