!> Axial vibrating bar (METHOD.md section 6.5) through the Fortran module, in 2D or 3D.
!>
!>   usage: vibrating_bar_f <2|3> <output file> [apic|mls]
!>
!> The same problem, set-up, checks and output as examples/c/vibrating_bar.c, computed with the
!> same operations in the same order, so the particle file equals the C one value for value:
!> bar L = 1 fixed at x = 0 and free at x = L, v(X, t) = v0 cos(omega t) sin(beta X),
!> beta = pi / (2 L), omega = beta sqrt(E / rho); 32 cells along the bar (grid 40 x 4 (x 4)),
!> 2 particles per cell per direction, E = 100, rho = 1, nu = 0, quadratic B-spline, APIC (or MLS
!> when the third argument says so), USL,
!> dt = stable_dt(0.2), run to one period T with the last step shortened.
!> Checks: max |v_cm - exact| <= 3% of v0 S and the period from the zero crossings of v_cm within
!> 1% of T. Writes one particle per line: positions, then velocities (17 significant digits).
program vibrating_bar
   use, intrinsic :: iso_c_binding, only: c_double, c_int32_t, c_int64_t, c_size_t
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use rkmpm
   implicit none (type, external)

   real(c_double), parameter :: pi = 3.14159265358979323846_c_double
   real(c_double), parameter :: bar_length = 1, young = 100, density = 1, poisson = 0
   real(c_double), parameter :: v0 = 0.01_c_double, cfl = 0.2_c_double

   type(rkmpm_sim) :: sim
   character(len=4096) :: arg, out_path
   integer :: dim, nx, ny, nz, i, j, k, p, count, unit, ios, s, steps
   integer(c_int32_t) :: material
   real(c_double) :: beta, omega, period, h, hp, volume, total_mass, weighted_sin, sin_average
   real(c_double) :: amplitude, dt, dt_step, t, momentum, v_cm, exact, error, max_error
   real(c_double) :: a, b, t_down, t_up, relative_error, measured, period_error
   real(c_double), allocatable :: x(:, :), v(:, :), vol(:), mass(:), x_ref(:, :), t_hist(:), v_hist(:)
   logical :: failed, mls
   type(rkmpm_energies) :: e0, e1
   type(rkmpm_momenta) :: pm
   type(rkmpm_energy_balance) :: balance
   real(c_double) :: kinetic, linear(3), angular(3), xp(3), vp(3)

   if (command_argument_count() /= 2 .and. command_argument_count() /= 3) call usage()
   mls = .false.
   if (command_argument_count() == 3) then
      call get_command_argument(3, arg)
      if (trim(arg) == 'mls') then
         mls = .true.
      else if (trim(arg) /= 'apic') then
         call usage()
      end if
   end if
   call get_command_argument(1, arg)
   if (trim(arg) == '2') then
      dim = 2
   else if (trim(arg) == '3') then
      dim = 3
   else
      call usage()
   end if
   call get_command_argument(2, out_path)

   if (rkmpm_library_abi_version() /= RKMPM_BINDING_ABI_VERSION) then
      write (error_unit, '(a, i0, a, i0)') 'ABI mismatch: library ', rkmpm_library_abi_version(), &
         ', bindings ', RKMPM_BINDING_ABI_VERSION
      error stop 1
   end if

   ! Problem (the same expressions as the C driver).
   beta = pi/(2.0_c_double*bar_length)
   omega = beta*sqrt(young/density)
   period = 2.0_c_double*pi/omega

   ! Grid: 32 cells along the bar, 40 in x, 4 across; origin 0.
   h = bar_length/32.0_c_double
   if (dim == 2) then
      call sim%init([0.0_c_double, 0.0_c_double], [40, 4], h)
      call sim%set_gravity([0.0_c_double, 0.0_c_double])
   else
      call sim%init([0.0_c_double, 0.0_c_double, 0.0_c_double], [40, 4, 4], h)
      call sim%set_gravity([0.0_c_double, 0.0_c_double, 0.0_c_double])
   end if
   call sim%set_shape(RKMPM_SHAPE_BSPLINE2)
   call sim%set_integration(RKMPM_INTEGRATION_MP)
   if (mls) then
      call sim%set_transfer(RKMPM_TRANSFER_MLS)
   else
      call sim%set_transfer(RKMPM_TRANSFER_APIC)
   end if
   call sim%set_scheme(RKMPM_SCHEME_USL)
   call sim%set_boundary(0, RKMPM_SIDE_LOW, RKMPM_BOUNDARY_FIXED)
   call sim%add_material_linear_elastic(density, young, poisson, material)

   ! Particles: 2 per cell per direction at the sub-cell centres; x fastest, then y, then z.
   nx = 64
   ny = 4
   nz = merge(4, 1, dim == 3)
   count = nx*ny*nz
   hp = h/2.0_c_double
   if (dim == 3) then
      volume = hp*hp*hp
   else
      volume = hp*hp
   end if
   allocate (x(dim, count), v(dim, count), vol(count), mass(count), x_ref(dim, count))
   p = 0
   do k = 0, nz - 1
      do j = 0, ny - 1
         do i = 0, nx - 1
            p = p + 1
            x(1, p) = (real(i, c_double) + 0.5_c_double)*hp
            x(2, p) = h + (real(j, c_double) + 0.5_c_double)*hp
            if (dim == 3) x(3, p) = h + (real(k, c_double) + 0.5_c_double)*hp
            v(:, p) = 0
            v(1, p) = v0*sin(beta*x(1, p))
            vol(p) = volume
         end do
      end do
   end do
   call sim%add_particles(material, x, vol, v)
   if (sim%particle_count() /= int(count, c_size_t)) then
      write (error_unit, '(a, i0, a, i0)') 'particle count ', sim%particle_count(), ', expected ', count
      error stop 1
   end if
   if (sim%dim() /= dim) error stop 'wrong dimension'

   ! Masses and reference positions give the sin-average S of the exact solution.
   if (sim%field_len(RKMPM_FIELD_MASS) /= int(count, c_size_t)) error stop 'wrong mass field length'
   call sim%get_particles(RKMPM_FIELD_MASS, mass)
   call sim%get_particles(RKMPM_FIELD_REFERENCE_POSITION, x_ref)
   total_mass = 0
   weighted_sin = 0
   do p = 1, count
      total_mass = total_mass + mass(p)
      weighted_sin = weighted_sin + mass(p)*sin(beta*x_ref(1, p))
   end do
   sin_average = weighted_sin/total_mass
   amplitude = v0*sin_average

   ! The energies and momenta the library reports are the particles' own sums (the initial
   ! state: no stress, no gravity).
   e0 = sim%energies()
   pm = sim%momenta()
   kinetic = 0
   linear = 0
   angular = 0
   do p = 1, count
      xp = 0
      vp = 0
      xp(1:dim) = x(:, p)
      vp(1:dim) = v(:, p)
      kinetic = kinetic + 0.5_c_double*mass(p)*sum(vp**2)
      linear = linear + mass(p)*vp
      angular = angular + mass(p)*[xp(2)*vp(3) - xp(3)*vp(2), xp(3)*vp(1) - xp(1)*vp(3), &
                                   xp(1)*vp(2) - xp(2)*vp(1)]
   end do
   if (abs(e0%kinetic - kinetic) > 1e-12_c_double*kinetic .or. e0%stored /= 0 .or. &
       e0%gravitational /= 0) then
      write (error_unit, '(a, 3es24.16)') 'energies ', e0%kinetic, e0%stored, e0%gravitational
      error stop 'sim%energies() is not the particles'' kinetic energy'
   end if
   if (any(abs(pm%linear - linear) > 1e-12_c_double*maxval(abs(linear))) .or. &
       any(abs(pm%angular - angular) > 1e-12_c_double*maxval(abs(angular)))) then
      write (error_unit, '(a, 6es24.16)') 'momenta ', pm%linear, pm%angular
      error stop 'sim%momenta() is not the particles'' momenta'
   end if

   ! Where the energy goes over the period: accounted from here on.
   call sim%set_energy_accounting(.true.)

   ! Time step: CFL 0.2 of the initial state; the last step is shortened to end on T.
   dt = sim%stable_dt(cfl)
   steps = int(ceiling(period/dt - 1e-9_c_double))
   allocate (t_hist(0:steps), v_hist(0:steps))

   max_error = 0
   t = 0
   do s = 0, steps
      if (s > 0) then
         if (s < steps) then
            dt_step = dt
         else
            dt_step = period - t
         end if
         call sim%step(dt_step)
         t = sim%time()
      end if
      call sim%get_particles(RKMPM_FIELD_VELOCITY, v)
      momentum = 0
      do p = 1, count
         momentum = momentum + mass(p)*v(1, p)
      end do
      v_cm = momentum/total_mass
      exact = amplitude*cos(omega*t)
      error = abs(v_cm - exact)
      if (error > max_error) max_error = error
      t_hist(s) = t
      v_hist(s) = v_cm
   end do
   if (sim%step_count() /= int(steps, c_int64_t)) error stop 'wrong step count'

   ! Period from the first downward and the following upward zero crossing.
   t_down = -1
   t_up = -1
   do s = 1, steps
      a = v_hist(s - 1)
      b = v_hist(s)
      if (t_down < 0) then
         if (a > 0 .and. b <= 0) t_down = t_hist(s - 1) + (t_hist(s) - t_hist(s - 1))*a/(a - b)
      else if (a < 0 .and. b >= 0) then
         t_up = t_hist(s - 1) + (t_hist(s) - t_hist(s - 1))*a/(a - b)
         exit
      end if
   end do

   failed = .false.
   relative_error = max_error/amplitude
   write (output_unit, '(a, i0, a, i0, a, i0, a, es12.6, a, f11.9, a, es24.16e3)') 'vibrating bar ', dim, &
      'D (Fortran): ', count, ' particles, ', steps, ' steps of dt = ', dt, ', T = ', period, ', final t = ', t
   write (output_unit, '(a, es12.6, a, f6.4, a, es15.9)') '  max |v_cm - exact| = ', max_error, ' = ', &
      100*relative_error, '% of v0*S (limit 3%), v0*S = ', amplitude
   if (.not. (relative_error <= 0.03_c_double)) then
      write (output_unit, '(a)') '  FAIL: velocity error above 3%'
      failed = .true.
   end if
   if (t_down < 0 .or. t_up < 0) then
      write (output_unit, '(a)') '  FAIL: v_cm did not cross zero downward and then upward within one period'
      failed = .true.
   else
      measured = 2.0_c_double*(t_up - t_down)
      period_error = abs(measured - period)/period
      write (output_unit, '(4(a, f11.9), a)') '  zero crossings t1 = ', t_down, ' (T/4 = ', 0.25_c_double*period, &
         '), t2 = ', t_up, ' (3T/4 = ', 0.75_c_double*period, ')'
      write (output_unit, '(2(a, f11.9), a, f6.4, a)') '  measured period ', measured, ' vs T = ', period, &
         ': relative error ', 100*period_error, '% (limit 1%)'
      if (.not. (period_error <= 0.01_c_double)) then
         write (output_unit, '(a)') '  FAIL: period error above 1%'
         failed = .true.
      end if
   end if

   ! Energy after one period: no gravity, and the fixed end does no work, so what is gone is
   ! the scheme's.
   e1 = sim%energies()
   write (output_unit, '(a, es12.6, a, es12.6, a, es12.6, a)') '  energy: kinetic + stored ', &
      e0%kinetic + e0%stored, ' at the start, ', e1%kinetic + e1%stored, ' after a period (', &
      e1%stored, ' stored)'
   if (.not. (e1%kinetic + e1%stored <= 1.01_c_double*(e0%kinetic + e0%stored))) then
      write (output_unit, '(a)') '  FAIL: the bar gained more than 1% energy'
      failed = .true.
   end if
   ! The ledger: the bar is elastic, so the stress work is the change of its stored energy (to
   ! the trapezoidal rule's error), and what is gone is the scheme's (other_dissipation).
   balance = sim%energy_balance()
   write (output_unit, '(a, es12.5, a, es12.5, a, es12.5)') '  ledger: stress work ', &
      balance%stress_work, ', material dissipation ', balance%material_dissipation, &
      ', scheme ', balance%other_dissipation
   if (.not. (balance%kinetic == e1%kinetic .and. balance%start == e0%kinetic + e0%stored .and. &
              abs(balance%material_dissipation) <= 1e-4_c_double*balance%start .and. &
              abs(e1%kinetic + e1%stored - (balance%start - balance%other_dissipation)) <= &
              1e-9_c_double*balance%start)) then
      write (output_unit, '(a)') '  FAIL: the energy balance does not close'
      failed = .true.
   end if

   ! Final state: positions then velocities, one particle per line.
   call sim%get_particles(RKMPM_FIELD_POSITION, x)
   call sim%get_particles(RKMPM_FIELD_VELOCITY, v)
   open (newunit=unit, file=trim(out_path), status='replace', action='write', iostat=ios)
   if (ios /= 0) then
      write (error_unit, '(2a)') 'cannot open ', trim(out_path)
      error stop 1
   end if
   do p = 1, count
      write (unit, '(*(es24.16e3, :, 1x))') x(:, p), v(:, p)
   end do
   close (unit)

   call sim%free()
   call sim%free()   ! idempotent
   deallocate (x, v, vol, mass, x_ref, t_hist, v_hist)
   if (failed) then
      write (output_unit, '(a)') '  FAILED'
      error stop 1
   end if
   write (output_unit, '(a)') '  passed'

contains

   subroutine usage()
      write (error_unit, '(a)') 'usage: vibrating_bar_f <2|3> <output file> [apic|mls]'
      error stop 2
   end subroutine usage

end program vibrating_bar
