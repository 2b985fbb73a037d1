/*
 * Axial vibrating bar (METHOD.md section 6.5) through the C API, in 2D or 3D.
 *
 *   usage: vibrating_bar <2|3> <output file> [apic|mls]
 *
 * A bar of length L = 1 along x, fixed at x = 0 and free at x = L, vibrates in its first mode:
 *   v(X, t) = v0 cos(omega t) sin(beta X),  beta = pi / (2 L),  omega = beta sqrt(E / rho).
 * With Poisson's ratio 0 the motion is exactly one-dimensional, so the 2D and 3D bars (a few
 * cells thick) must follow the 1D answer. The mass-weighted mean x-velocity of the particles is
 *   v_cm(t) = v0 cos(omega t) S,  S = sum_p m_p sin(beta X_p) / sum_p m_p,
 * recorded after every step over one period T = 2 pi / omega.
 *
 * Checks (the tolerances are those of the project brief):
 *  - max_t |v_cm - exact| <= 3% of v0 S (amplitude and phase error of a 32-cell bar over one
 *    period, with quadratic B-splines and APIC, or MLS when asked for);
 *  - the period measured from the first downward (T/4) and upward (3T/4) zero crossings of v_cm,
 *    linearly interpolated between steps, is within 1% of T.
 * Writes the final particle positions and velocities, one particle per line ("%.17g"), so the
 * C, Fortran and Rust drivers can be compared value by value.
 */
#include "rkmpm.h"
#include "rkmpm_check.h"

#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PI 3.14159265358979323846

int main(int argc, char **argv) {
  const int mls = argc == 4 && strcmp(argv[3], "mls") == 0;
  if ((argc != 3 && argc != 4) || (strcmp(argv[1], "2") != 0 && strcmp(argv[1], "3") != 0) ||
      (argc == 4 && !mls && strcmp(argv[3], "apic") != 0)) {
    fprintf(stderr, "usage: %s <2|3> <output file> [apic|mls]\n",
            argc > 0 ? argv[0] : "vibrating_bar");
    return EXIT_FAILURE;
  }
  const uint32_t dim = (uint32_t)atoi(argv[1]);
  const char *out_path = argv[2];

  if (rkmpm_abi_version() != RKMPM_ABI_VERSION) {
    fprintf(stderr, "ABI mismatch: library %u, header %u\n", (unsigned)rkmpm_abi_version(),
            (unsigned)RKMPM_ABI_VERSION);
    return EXIT_FAILURE;
  }

  /* Problem. */
  const double bar_length = 1.0;
  const double young = 100.0, density = 1.0, poisson = 0.0;
  const double v0 = 0.01;
  const double beta = PI / (2.0 * bar_length);
  const double omega = beta * sqrt(young / density);
  const double period = 2.0 * PI / omega;
  const double cfl = 0.2;

  /* Grid: 32 cells along the bar, 40 in x, 4 across; origin 0. */
  const double h = bar_length / 32.0;
  const double origin[3] = {0.0, 0.0, 0.0};
  const size_t cells[3] = {40, 4, 4};

  RkmpmSim *sim = NULL;
  RKMPM_CHECK(rkmpm_sim_new(dim, origin, cells, h, &sim));
  RKMPM_CHECK(rkmpm_sim_set_shape(sim, RKMPM_SHAPE_BSPLINE2, 0, 0.0));
  RKMPM_CHECK(rkmpm_sim_set_integration(sim, RKMPM_INTEGRATION_MP, 0));
  RKMPM_CHECK(rkmpm_sim_set_transfer(sim, mls ? RKMPM_TRANSFER_MLS : RKMPM_TRANSFER_APIC, 0.0));
  RKMPM_CHECK(rkmpm_sim_set_scheme(sim, RKMPM_SCHEME_USL));
  const double no_gravity[3] = {0.0, 0.0, 0.0};
  RKMPM_CHECK(rkmpm_sim_set_gravity(sim, no_gravity));
  RKMPM_CHECK(rkmpm_sim_set_boundary(sim, 0, -1, RKMPM_BOUNDARY_FIXED, 0.0));
  uint32_t material = 0;
  RKMPM_CHECK(rkmpm_sim_add_material_linear_elastic(sim, density, young, poisson, &material));

  /* Particles: 2 per cell per direction at the centres of the sub-cells; the bar occupies
     x in [0, L] and y (and z) in [h, 3h]. Index order: x fastest, then y, then z. */
  const size_t nx = 64, ny = 4, nz = (dim == 3) ? 4 : 1;
  const size_t count = nx * ny * nz;
  const double hp = h / 2.0;
  double *x = malloc(count * dim * sizeof *x);
  double *v = malloc(count * dim * sizeof *v);
  double *vol = malloc(count * sizeof *vol);
  if (x == NULL || v == NULL || vol == NULL) {
    fprintf(stderr, "out of memory\n");
    return EXIT_FAILURE;
  }
  const double volume = (dim == 3) ? hp * hp * hp : hp * hp;
  size_t p = 0;
  for (size_t k = 0; k < nz; ++k) {
    for (size_t j = 0; j < ny; ++j) {
      for (size_t i = 0; i < nx; ++i) {
        x[p * dim + 0] = ((double)i + 0.5) * hp;
        x[p * dim + 1] = h + ((double)j + 0.5) * hp;
        if (dim == 3) {
          x[p * dim + 2] = h + ((double)k + 0.5) * hp;
        }
        for (uint32_t d = 0; d < dim; ++d) {
          v[p * dim + d] = 0.0;
        }
        v[p * dim + 0] = v0 * sin(beta * x[p * dim + 0]);
        vol[p] = volume;
        ++p;
      }
    }
  }
  RKMPM_CHECK(rkmpm_sim_add_particles(sim, material, count, x, vol, v));
  if (rkmpm_sim_particle_count(sim) != count) {
    fprintf(stderr, "particle count %zu, expected %zu\n", rkmpm_sim_particle_count(sim), count);
    return EXIT_FAILURE;
  }

  /* Masses and reference positions give the sin-average S of the exact solution. */
  double *mass = malloc(count * sizeof *mass);
  double *x_ref = malloc(count * dim * sizeof *x_ref);
  if (mass == NULL || x_ref == NULL) {
    fprintf(stderr, "out of memory\n");
    return EXIT_FAILURE;
  }
  size_t len = 0;
  RKMPM_CHECK(rkmpm_sim_field_len(sim, RKMPM_FIELD_MASS, &len));
  if (len != count) {
    fprintf(stderr, "mass field length %zu, expected %zu\n", len, count);
    return EXIT_FAILURE;
  }
  RKMPM_CHECK(rkmpm_sim_get_particles(sim, RKMPM_FIELD_MASS, mass, count));
  RKMPM_CHECK(rkmpm_sim_get_particles(sim, RKMPM_FIELD_REFERENCE_POSITION, x_ref, count * dim));
  double total_mass = 0.0, weighted_sin = 0.0;
  for (p = 0; p < count; ++p) {
    total_mass += mass[p];
    weighted_sin += mass[p] * sin(beta * x_ref[p * dim + 0]);
  }
  const double sin_average = weighted_sin / total_mass;
  const double amplitude = v0 * sin_average;

  /* Time step: CFL 0.2 of the initial state; the last step is shortened to end on T. */
  double dt = 0.0;
  RKMPM_CHECK(rkmpm_sim_stable_dt(sim, cfl, &dt));
  const long steps = (long)ceil(period / dt - 1e-9);
  double *t_hist = malloc((size_t)(steps + 1) * sizeof *t_hist);
  double *v_hist = malloc((size_t)(steps + 1) * sizeof *v_hist);
  if (t_hist == NULL || v_hist == NULL) {
    fprintf(stderr, "out of memory\n");
    return EXIT_FAILURE;
  }

  double max_error = 0.0;
  double t = 0.0;
  for (long s = 0; s <= steps; ++s) {
    if (s > 0) {
      const double dt_step = (s < steps) ? dt : period - t;
      RKMPM_CHECK(rkmpm_sim_step(sim, dt_step));
      RKMPM_CHECK(rkmpm_sim_time(sim, &t));
    }
    RKMPM_CHECK(rkmpm_sim_get_particles(sim, RKMPM_FIELD_VELOCITY, v, count * dim));
    double momentum = 0.0;
    for (p = 0; p < count; ++p) {
      momentum += mass[p] * v[p * dim + 0];
    }
    const double v_cm = momentum / total_mass;
    const double exact = amplitude * cos(omega * t);
    const double error = fabs(v_cm - exact);
    if (error > max_error) {
      max_error = error;
    }
    t_hist[s] = t;
    v_hist[s] = v_cm;
  }
  uint64_t step_count = 0;
  RKMPM_CHECK(rkmpm_sim_step_count(sim, &step_count));
  if (step_count != (uint64_t)steps) {
    fprintf(stderr, "step count %llu, expected %ld\n", (unsigned long long)step_count, steps);
    return EXIT_FAILURE;
  }

  /* Period from the first downward and the following upward zero crossing. */
  double t_down = -1.0, t_up = -1.0;
  for (long s = 1; s <= steps; ++s) {
    const double a = v_hist[s - 1], b = v_hist[s];
    if (t_down < 0.0) {
      if (a > 0.0 && b <= 0.0) {
        t_down = t_hist[s - 1] + (t_hist[s] - t_hist[s - 1]) * a / (a - b);
      }
    } else if (a < 0.0 && b >= 0.0) {
      t_up = t_hist[s - 1] + (t_hist[s] - t_hist[s - 1]) * a / (a - b);
      break;
    }
  }

  int failed = 0;
  const double relative_error = max_error / amplitude;
  printf("vibrating bar %uD (C): %zu particles, %ld steps of dt = %.6e, T = %.9f, final t = %.17g\n",
         (unsigned)dim, count, steps, dt, period, t);
  printf("  max |v_cm - exact| = %.6e = %.4f%% of v0*S (limit 3%%), v0*S = %.9e\n", max_error,
         100.0 * relative_error, amplitude);
  if (!(relative_error <= 0.03)) {
    printf("  FAIL: velocity error above 3%%\n");
    failed = 1;
  }
  if (t_down < 0.0 || t_up < 0.0) {
    printf("  FAIL: v_cm did not cross zero downward and then upward within one period\n");
    failed = 1;
  } else {
    const double measured = 2.0 * (t_up - t_down);
    const double period_error = fabs(measured - period) / period;
    printf("  zero crossings t1 = %.9f (T/4 = %.9f), t2 = %.9f (3T/4 = %.9f)\n", t_down,
           0.25 * period, t_up, 0.75 * period);
    printf("  measured period %.9f vs T = %.9f: relative error %.4f%% (limit 1%%)\n", measured,
           period, 100.0 * period_error);
    if (!(period_error <= 0.01)) {
      printf("  FAIL: period error above 1%%\n");
      failed = 1;
    }
  }

  /* Final state: positions then velocities, one particle per line. */
  RKMPM_CHECK(rkmpm_sim_get_particles(sim, RKMPM_FIELD_POSITION, x, count * dim));
  RKMPM_CHECK(rkmpm_sim_get_particles(sim, RKMPM_FIELD_VELOCITY, v, count * dim));
  FILE *out = fopen(out_path, "w");
  if (out == NULL) {
    perror(out_path);
    return EXIT_FAILURE;
  }
  for (p = 0; p < count; ++p) {
    for (uint32_t d = 0; d < dim; ++d) {
      fprintf(out, "%.17g ", x[p * dim + d]);
    }
    for (uint32_t d = 0; d < dim; ++d) {
      fprintf(out, (d + 1 < dim) ? "%.17g " : "%.17g\n", v[p * dim + d]);
    }
  }
  if (fclose(out) != 0) {
    perror(out_path);
    return EXIT_FAILURE;
  }

  rkmpm_sim_free(sim);
  free(x);
  free(v);
  free(vol);
  free(mass);
  free(x_ref);
  free(t_hist);
  free(v_hist);
  printf("  %s\n", failed ? "FAILED" : "passed");
  return failed ? EXIT_FAILURE : EXIT_SUCCESS;
}
