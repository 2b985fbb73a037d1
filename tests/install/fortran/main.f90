!> An outside Fortran program using an installed rkmpm (scripts/test-install.sh builds it with
!> CMake and with pkg-config). The same problem and checks as ../c/main.c: a 3 x 3 block of
!> particles in free fall with a uniform initial velocity must keep v0 + g t and move by the sum
!> of dt * v. Stops with a non-zero code on any failure (a failing rkmpm call stops by itself).
program app
   use, intrinsic :: iso_c_binding, only: c_double, c_int32_t, c_int64_t
   use, intrinsic :: iso_fortran_env, only: error_unit
   use rkmpm
   implicit none (type, external)

   integer, parameter :: n = 9, steps = 5
   real(c_double), parameter :: h = 1.0_c_double/16, gravity(2) = [0.0_c_double, -9.81_c_double]
   real(c_double), parameter :: v0(2) = [0.5_c_double, 0.25_c_double]
   type(rkmpm_sim) :: sim
   real(c_double) :: x(2, n), v(2, n), vol(n), expected(2, n), out(2, n), dt, t, worst
   integer(c_int32_t) :: material
   integer(c_int64_t) :: taken
   integer :: p, s
   logical :: failed

   if (rkmpm_library_abi_version() /= RKMPM_BINDING_ABI_VERSION) then
      write (error_unit, '(a, i0, a, i0)') 'FAIL: library ABI ', rkmpm_library_abi_version(), &
         ', module ABI ', RKMPM_BINDING_ABI_VERSION
      error stop 1
   end if
   do p = 1, n
      x(1, p) = 0.5_c_double + (mod(p - 1, 3) - 1)*0.5_c_double*h
      x(2, p) = 0.5_c_double + ((p - 1)/3 - 1)*0.5_c_double*h
      v(:, p) = v0
   end do
   vol = 0.25_c_double*h*h
   expected = x

   call sim%init([0.0_c_double, 0.0_c_double], [16, 16], h)
   call sim%set_gravity(gravity)
   call sim%add_material_linear_elastic(1000.0_c_double, 1.0e6_c_double, 0.3_c_double, material)
   call sim%add_particles(material, x, vol, v)
   t = 0
   do s = 1, steps
      dt = sim%stable_dt(0.5_c_double)
      call sim%step(dt)
      t = t + dt
      do p = 1, n
         expected(:, p) = expected(:, p) + dt*(v0 + gravity*t)
      end do
   end do

   taken = sim%step_count()
   failed = taken /= steps .or. sim%particle_count() /= n
   call sim%get_particles(RKMPM_FIELD_POSITION, out)
   worst = maxval(abs(out - expected))
   failed = failed .or. .not. (worst <= 1.0e-12_c_double)
   call sim%get_particles(RKMPM_FIELD_VELOCITY, out)
   do p = 1, n
      failed = failed .or. .not. all(abs(out(:, p) - (v0 + gravity*t)) <= 1.0e-10_c_double)
   end do
   call sim%free()

   print '(a, a, a, i0, a, i0, a, es12.6, a, f11.9, a, f11.9, a, es8.2)', 'rkmpm ', rkmpm_version_string(), &
      ' (ABI ', rkmpm_library_abi_version(), '): ', taken, ' steps to t = ', t, ' s, particle 1 at (', &
      expected(1, 1), ', ', expected(2, 1), '), worst position error ', worst
   if (failed) error stop 'FAIL'
end program app
