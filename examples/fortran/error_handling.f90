!> Deliberate misuse through the idiomatic Fortran layer: each failing call passes `stat` and
!> `errmsg`, and the driver checks the exact status, that a message came back, and where
!> meaningful that the simulation is unchanged. Together with vibrating_bar.f90 it calls every
!> raw binding of module rkmpm at least once (a misspelt binding name fails at link time already,
!> since the whole module object is linked). Stops with a non-zero code on any mismatch.
!>
!>   usage: error_handling_f          run the checks
!>          error_handling_f stop     make a failing call without `stat` (must error-stop)

!> Body-force callbacks (bind(C) procedures cannot be internal procedures).
module error_handling_callbacks
   use, intrinsic :: iso_c_binding, only: c_ptr, c_double, c_size_t, c_int32_t, c_int64_t, c_f_pointer, &
                                          c_associated
   implicit none (type, external)
   private
   public :: force_data, FORCE_RECORD, FORCE_FAIL, FORCE_CONVERGE, body_force
   public :: progress_data, progress

   integer, parameter :: FORCE_RECORD = 0, FORCE_FAIL = 1, FORCE_CONVERGE = 2

   type :: force_data
      integer :: mode = FORCE_RECORD
      integer :: calls = 0
      integer(c_size_t) :: last_count = 0
      integer(c_int32_t) :: last_dim = 0
      real(c_double) :: last_time = -1
      real(c_double) :: k = 0, center = 0
   end type force_data

   !> Counts the calls of the progress callback and stops the run at call `stop_at`.
   type :: progress_data
      integer :: calls = 0, stop_at = 0
      integer(c_int64_t) :: last_steps = -1
      real(c_double) :: last_time = -1, last_end = -1
   end type progress_data

contains

   integer(c_int32_t) function body_force(user_data, time, count, dim, reference_positions, positions, &
                                          accelerations) bind(C)
      type(c_ptr), value :: user_data
      real(c_double), value :: time
      integer(c_size_t), value :: count
      integer(c_int32_t), value :: dim
      real(c_double), intent(in) :: reference_positions(dim, count)
      real(c_double), intent(in) :: positions(dim, count)
      real(c_double), intent(inout) :: accelerations(dim, count)
      type(force_data), pointer :: data
      body_force = 3
      if (.not. c_associated(user_data)) return
      call c_f_pointer(user_data, data)
      data%calls = data%calls + 1
      data%last_count = count
      data%last_dim = dim
      data%last_time = time
      select case (data%mode)
      case (FORCE_RECORD)
         ! Gravity-like, and a use of the reference positions.
         accelerations = 0
         accelerations(2, :) = -1 + 0*reference_positions(2, :)
         body_force = 0
      case (FORCE_FAIL)
         body_force = 1
      case (FORCE_CONVERGE)
         accelerations = 0
         accelerations(1, :) = -data%k*(positions(1, :) - data%center)
         body_force = 0
      end select
   end function body_force

   integer(c_int32_t) function progress(user_data, steps, time, end_time, dt) bind(C)
      type(c_ptr), value :: user_data
      integer(c_int64_t), value :: steps
      real(c_double), value :: time, end_time, dt
      type(progress_data), pointer :: data
      call c_f_pointer(user_data, data)
      data%calls = data%calls + 1
      data%last_steps = steps
      data%last_time = time
      data%last_end = end_time
      progress = 0
      if (dt <= 0 .or. data%calls == data%stop_at) progress = 1
   end function progress

end module error_handling_callbacks

program error_handling
   use, intrinsic :: iso_c_binding, only: c_double, c_int, c_int32_t, c_int64_t, c_size_t, c_loc
   use, intrinsic :: iso_fortran_env, only: output_unit, error_unit
   use, intrinsic :: ieee_arithmetic, only: ieee_value, ieee_quiet_nan
   use rkmpm
   use error_handling_callbacks
   implicit none (type, external)

   real(c_double), parameter :: h = 0.1_c_double
   integer :: failures = 0, checks = 0
   type(rkmpm_sim) :: sim, unused
   integer(c_int) :: st, code
   character(:), allocatable :: msg
   integer(c_int32_t) :: mat, mat2, mat3
   type(rkmpm_johnson_cook) :: jc
   real(c_double) :: nan, dt, critical, t0
   real(c_double) :: x(2, 64), vol(64), v(2, 64), buf(130), pos(2, 64), pos_after(2, 64)
   real(c_double), allocatable :: wrong(:, :)
   integer :: i, j, p
   integer(c_size_t) :: n0
   integer(c_int64_t) :: steps0, taken, iterations
   real(c_double) :: tolerance
   type(force_data), target :: force
   type(progress_data), target :: watch
   character(len=64) :: names(0:13)
   real(c_double) :: bx(2, 2), bn(2, 2)

   nan = ieee_value(0.0_c_double, ieee_quiet_nan)

   ! With the argument "stop": a failing call without `stat` must stop the program with the
   ! library's message (CTest checks the output of this run).
   if (command_argument_count() == 1) then
      call unused%step(1.0e-3_c_double)
      error stop 'not reached: step on an uninitialized rkmpm_sim did not stop'
   end if

   ! ---- library-level functions ----
   call expect_true(rkmpm_library_abi_version() == RKMPM_BINDING_ABI_VERSION, 'ABI version')
   call expect_true(len(rkmpm_version_string()) > 0, 'version string')
   write (output_unit, '(a, a, a, i0)') 'rkmpm ', rkmpm_version_string(), ', ABI ', rkmpm_library_abi_version()
   do code = 0, 13
      names(code) = rkmpm_status_string(code)
      call expect_true(len_trim(names(code)) > 0 .and. names(code) /= 'unknown status', 'status string')
      do i = 0, code - 1
         call expect_true(names(i) /= names(code), 'distinct status strings')
      end do
   end do
   call expect_true(rkmpm_status_string(99_c_int) == 'unknown status', 'status 99 is unknown')

   ! ---- an object that was never initialized: the NULL handle reaches C ----
   call expect_true(.not. unused%is_initialized(), 'a new object holds no simulation')
   call expect_true(unused%particle_count() == 0, 'particle count of an uninitialized object')
   call unused%step(1.0e-3_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_NULL_POINTER, msg, 'step without init')
   t0 = unused%time(stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_NULL_POINTER, msg, 'time without init')
   call unused%free()   ! a no-op

   ! ---- init ----
   call sim%init([0.0_c_double, 0.0_c_double], [10, 10, 10], h, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'init: origin and cells differ in size')
   call sim%init([0.0_c_double, 0.0_c_double, 0.0_c_double, 0.0_c_double], [10, 10, 10, 10], h, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'init: dimension 4')
   call sim%init([0.0_c_double, 0.0_c_double], [10, 10], -h, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'init: negative cell size')
   call expect_true(.not. sim%is_initialized(), 'failed init leaves the object empty')
   call sim%init([0.0_c_double, 0.0_c_double], [10, 10], h, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'init')
   call expect_true(allocated(msg), 'errmsg allocated on success')
   if (allocated(msg)) call expect_true(len(msg) == 0, 'errmsg empty on success')
   call sim%init([0.0_c_double, 0.0_c_double], [10, 10], h, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_STATE, msg, 'init twice')
   call expect_true(sim%dim() == 2, 'dim')

   ! ---- options ----
   call sim%set_gravity([0.0_c_double, nan], stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'NaN gravity')
   call sim%set_gravity([0.0_c_double, 0.0_c_double, 0.0_c_double], stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'gravity of the wrong size')
   call sim%set_boundary(0, 0, RKMPM_BOUNDARY_FIXED, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'boundary side 0')
   call sim%set_boundary(0, RKMPM_SIDE_LOW, 9, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'boundary kind 9')
   call sim%set_boundary(5, RKMPM_SIDE_HIGH, RKMPM_BOUNDARY_SLIP, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'boundary axis 5')
   call sim%set_boundary(1, RKMPM_SIDE_LOW, RKMPM_BOUNDARY_FRICTION, friction=0.3_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'friction wall')
   call sim%set_shape(77, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'shape 77')
   call sim%set_shape(RKMPM_SHAPE_RK, rk_order=2, rk_support=1.0_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'RK order 2 with a support too small')
   call sim%set_integration(RKMPM_INTEGRATION_VC, vc_order=0, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'VC order 0')
   call sim%vc_solve(tolerance, iterations, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'VC solve rule')
   call expect_true(tolerance == RKMPM_DEFAULT_VC_SOLVE_TOLERANCE .and. &
                    iterations == RKMPM_DEFAULT_VC_SOLVE_MAX_ITERATIONS, 'default VC solve rule')
   ! The automatic rule of the default shape, the quadratic B-spline, at order 1.
   call expect_true(sim%vc_solve_interval() == RKMPM_BSPLINE_VC_SOLVE_INTERVAL, &
                    'default VC solve interval')
   call sim%set_vc_solve_interval(-2_c_int32_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'VC solve interval of -2 steps')
   call sim%set_vc_solve_interval(2_c_int32_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'VC solve interval of 2 steps')
   call expect_true(sim%vc_solve_interval() == 2, 'VC solve interval kept')
   call expect_true(sim%vc_surface_refresh() == RKMPM_DEFAULT_VC_SURFACE_REFRESH, &
                    'default found-surface refresh')
   call sim%set_vc_surface_refresh(-2_c_int32_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'found-surface refresh of -2 steps')
   call sim%set_vc_surface_refresh(2_c_int32_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'found-surface refresh of 2 steps')
   call expect_true(sim%vc_surface_refresh() == 2, 'found-surface refresh kept')
   call sim%set_threads(2_c_int32_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'two threads of its own')
   call sim%set_threads(-1_c_int32_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'a negative thread count')
   call sim%set_threads(RKMPM_MAX_THREADS + 1_c_int32_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'more threads than RKMPM_MAX_THREADS')
   call expect_true(sim%threads() == 2, 'thread count kept')
   call sim%set_vc_solve(2.0_c_double, 10_c_int64_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'VC solve tolerance 2')
   call sim%set_vc_solve(1.0e-8_c_double, -1_c_int64_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'VC solve with -1 iterations')
   call sim%set_vc_solve(1.0e-8_c_double, 100_c_int64_t, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'VC solve 1e-8, 100 iterations')
   call sim%vc_solve(tolerance, iterations, stat=st, errmsg=msg)
   call expect_true(tolerance == 1.0e-8_c_double .and. iterations == 100, 'VC solve rule kept')
   call sim%set_transfer(RKMPM_TRANSFER_PIC_FLIP, flip_ratio=1.5_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'FLIP ratio 1.5')
   call sim%set_scheme(RKMPM_SCHEME_MUSL, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'MUSL')
   dt = sim%stable_dt(0.5_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_STATE, msg, 'stable_dt without particles')

   ! ---- materials ----
   call sim%add_material_linear_elastic(1.0_c_double, 100.0_c_double, 0.5_c_double, mat, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'Poisson ratio 0.5')
   call sim%add_material_linear_elastic(1.0_c_double, 100.0_c_double, 0.3_c_double, mat, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'linear elastic material')
   call sim%add_material_neo_hookean(1.0_c_double, 100.0_c_double, 0.3_c_double, mat2, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'neo-Hookean material')
   call expect_true(mat == 0 .and. mat2 == 1, 'material ids 0 and 1')
   call sim%add_material_drucker_prager(2650.0_c_double, 1e6_c_double, 0.3_c_double, 30.0_c_double, &
                                        0.0_c_double, 31.0_c_double, mat3, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'dilatancy above friction')
   jc%density = 8960; jc%young = 124e9_c_double; jc%poisson = 0.34_c_double
   jc%a = 90e6_c_double; jc%b = 292e6_c_double; jc%n = 0.31_c_double; jc%c = 0.025_c_double
   jc%reference_strain_rate = 1; jc%m = 1.09_c_double; jc%room_temperature = 298
   jc%melt_temperature = 1356; jc%specific_heat = 383; jc%taylor_quinney = 0.9_c_double
   jc%eos_enabled = 2
   call sim%add_material_johnson_cook(jc, mat3, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'Johnson-Cook eos flag 2')
   call sim%set_contact(.true., -1.0_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'negative contact friction')
   call sim%add_material_rigid(1000.0_c_double, [0.0_c_double], mat3, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'rigid velocity of the wrong length')
   call sim%set_rigid_velocity(0_c_int32_t, [0.0_c_double], stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'set_rigid_velocity of the wrong length')
   call sim%set_rigid_velocity(99_c_int32_t, [0.0_c_double, 0.0_c_double], stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_UNKNOWN_MATERIAL, msg, 'set_rigid_velocity of an unknown material')
   call sim%load('/nonexistent-dir/x.rkmpm', stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_STATE, msg, 'load into an initialized object')

   ! ---- particles: an 8 x 8 block on [0.3, 0.7]^2 ----
   p = 0
   do j = 0, 7
      do i = 0, 7
         p = p + 1
         x(1, p) = 0.3_c_double + (i + 0.5_c_double)*h/2
         x(2, p) = 0.3_c_double + (j + 0.5_c_double)*h/2
         v(:, p) = [0.05_c_double, -0.025_c_double]
      end do
   end do
   vol = h*h/4
   allocate (wrong(3, 64))
   wrong = 0.5_c_double
   call sim%add_particles(mat, wrong, vol, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'positions with 3 rows in 2D')
   call sim%add_particles(mat, x, vol(1:10), stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'too few volumes')
   call sim%add_particles(99, x, vol, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_UNKNOWN_MATERIAL, msg, 'material 99')
   call sim%add_particles(mat, x + 1, vol, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_OUTSIDE_GRID, msg, 'particles outside the grid')
   call expect_true(sim%particle_count() == 0, 'failed additions add nothing')
   call sim%add_particles(mat, x, vol, v, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'add particles')
   call expect_true(sim%particle_count() == 64, 'particle count 64')

   ! ---- boundary points ----
   bx = reshape([0.3_c_double, 0.4_c_double, 0.3_c_double, 0.6_c_double], [2, 2])
   bn = reshape([-0.05_c_double, 0.0_c_double, -0.05_c_double, 0.0_c_double], [2, 2])
   call sim%add_boundary_points(bx, bn(:, 1:1), stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'area normals of the wrong shape')
   call sim%add_boundary_points(bx, 0*bn, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'zero area normals')
   call sim%add_boundary_points(bx + 2, bn, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_OUTSIDE_GRID, msg, 'boundary points outside the grid')
   call sim%add_boundary_points(bx, bn, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'boundary points')
   call sim%add_boundary_points(bx, bn, tractions=0*bn, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'boundary points with tractions')
   call expect_true(sim%boundary_point_count() == 4, 'boundary point count 4')

   ! ---- reading fields ----
   buf = -12345
   call sim%get_particles(RKMPM_FIELD_POSITION, buf(1:127), stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_BUFFER_TOO_SMALL, msg, 'short buffer')
   call expect_true(all(buf == -12345), 'a too-short buffer is not written')
   call sim%get_particles(RKMPM_FIELD_POSITION, buf, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'positions into a longer buffer')
   call expect_true(all(buf(1:128) == reshape(x, [128])) .and. all(buf(129:) == -12345), 'positions read back')
   deallocate (wrong)
   allocate (wrong(3, 64))
   call sim%get_particles(RKMPM_FIELD_POSITION, wrong, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'out(3, n) for a 2D vector field')
   call sim%get_particles(77, buf, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'field 77')
   n0 = sim%field_len(77, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'field_len of field 77')
   call expect_true(sim%field_len(RKMPM_FIELD_STRESS) == 256, 'stress field length 4 x 64')

   ! ---- time steps ----
   critical = sim%stable_dt(1.0_c_double)
   dt = sim%stable_dt(0.4_c_double)
   ! RK of order 2 cannot run with APIC (the default transfer): the first step refuses it.
   call sim%set_shape(RKMPM_SHAPE_RK, rk_order=2, rk_support=3.0_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'RK order 2')
   call sim%step(dt, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_UNSUPPORTED, msg, 'RK order 2 with APIC')
   call sim%set_shape(RKMPM_SHAPE_BSPLINE2, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'back to the quadratic B-spline (a failed step is no first step)')
   call sim%set_transfer(RKMPM_TRANSFER_PIC_FLIP, flip_ratio=0.95_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'PIC/FLIP 0.95')
   call sim%get_particles(RKMPM_FIELD_POSITION, pos)
   ! ---- checkpoint: save, load into another object, same particle count and step count ----
   call sim%save('error_handling_f.rkmpm', stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'save a checkpoint')
   call unused%load('error_handling_f.rkmpm', stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'load the checkpoint')
   call expect_true(unused%particle_count() == sim%particle_count(), 'the loaded copy has the same particles')
   call expect_true(unused%step_count() == sim%step_count(), 'the loaded copy has the same step count')
   call unused%free()
   call unused%load('/nonexistent-dir/x.rkmpm', stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_IO, msg, 'load a missing file')
   call expect_true(.not. unused%is_initialized(), 'a failed load leaves no simulation')
   call sim%step(10*critical, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_UNSTABLE_TIME_STEP, msg, 'dt = 10 x critical')
   call sim%step(-dt, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'negative dt')
   ! (time() and step_count() are impure functions: read them into variables before combining
   ! them with .and., which gfortran may short-circuit.)
   t0 = sim%time()
   steps0 = sim%step_count()
   call expect_true(t0 == 0 .and. steps0 == 0, 'failed steps do not advance time')

   ! ---- the callback ----
   force%mode = FORCE_FAIL
   call sim%set_body_force(body_force, c_loc(force), stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'set the body force')
   call sim%step(dt, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_CALLBACK, msg, 'callback returning 1')
   call expect_true(force%calls == 1, 'the callback was called once')
   force%mode = FORCE_RECORD
   call sim%step(dt, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'step with a body force')
   call expect_true(force%calls == 2 .and. force%last_count == 64 .and. force%last_dim == 2 .and. &
                    force%last_time == 0, 'callback arguments')
   ! Converging body force that folds the block over within one step: det F < 0.
   force%mode = FORCE_CONVERGE
   force%k = 3/(dt*dt)
   force%center = 0.5_c_double
   call sim%get_particles(RKMPM_FIELD_POSITION, pos)
   t0 = sim%time()
   steps0 = sim%step_count()
   call sim%step(dt, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVERTED_PARTICLE, msg, 'inverted particle')
   call sim%get_particles(RKMPM_FIELD_POSITION, pos_after)
   call expect_true(all(pos_after == pos), 'a failed step leaves the positions unchanged')
   call expect_true(sim%time() == t0, 'a failed step leaves the time unchanged')
   call expect_true(sim%step_count() == steps0, 'a failed step leaves the step count unchanged')
   call sim%set_body_force(stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'remove the body force')
   call sim%step(dt)
   call expect_true(force%calls == 3, 'a removed callback is not called')
   call expect_true(sim%step_count() == 2, 'two successful steps')

   ! ---- options fixed by the first step ----
   call sim%set_shape(RKMPM_SHAPE_LINEAR, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_STATE, msg, 'shape after a step')
   call sim%set_transfer(RKMPM_TRANSFER_APIC, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_STATE, msg, 'transfer after a step')
   call sim%set_scheme(RKMPM_SCHEME_USL, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_STATE, msg, 'scheme after a step')
   call sim%set_integration(RKMPM_INTEGRATION_MP, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_STATE, msg, 'integration after a step')
   call sim%set_gravity([0.0_c_double, -9.81_c_double], stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'gravity after a step')

   ! ---- adaptive steps ----
   call sim%advance(10*dt, 1.5_c_double, taken, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'advance with cfl 1.5')
   call expect_true(taken == 0, 'an invalid cfl takes no step')
   call sim%advance(-dt, 0.4_c_double, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_INVALID_ARGUMENT, msg, 'advance by a negative duration')
   t0 = sim%time()
   call sim%advance(3.5_c_double*dt, 0.5_c_double, taken, stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'advance by 3.5 dt at cfl 0.5')
   call expect_true(taken >= 2, 'advance took at least 2 steps (stable steps of about 1.25 dt)')
   call expect_true(sim%time() == t0 + 3.5_c_double*dt, 'advance ends exactly at the requested time')
   ! The progress callback sees every step and can stop the run: two steps stand.
   watch%stop_at = 2
   call sim%set_progress(progress, c_loc(watch), stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'set the progress callback')
   steps0 = sim%step_count()
   call sim%advance(100*dt, 0.5_c_double, taken, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_CALLBACK, msg, 'advance stopped by the progress callback')
   call expect_true(taken == 2 .and. watch%calls == 2, 'two steps, two progress calls')
   call expect_true(watch%last_steps == steps0 + 2, 'the callback gets the step count')
   call expect_true(watch%last_time == sim%time(), 'the callback gets the time')
   call sim%set_progress(stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'remove the progress callback')
   call sim%advance(dt, 0.5_c_double, taken)
   call expect_true(watch%calls == 2, 'a removed progress callback is not called')

   ! ---- files ----
   call sim%write_vtk('rkmpm-no-such-directory/particles.vtu', stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_IO, msg, 'write_vtk into a missing directory')
   call sim%write_vtk_frame('rkmpm-no-such-directory/frames', stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_IO, msg, 'write_vtk_frame into a missing directory')
   call sim%write_vtk('error_handling_f.vtu', stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'write_vtk')
   call sim%write_vtk_frame('error_handling_f_series', stat=st, errmsg=msg)
   call expect(st, RKMPM_OK, msg, 'write_vtk_frame')

   call sim%free()
   call expect_true(.not. sim%is_initialized(), 'free nulls the handle')
   call sim%free()
   call sim%step(dt, stat=st, errmsg=msg)
   call expect(st, RKMPM_ERR_NULL_POINTER, msg, 'step after free')

   write (output_unit, '(i0, a, i0, a)') checks, ' checks, ', failures, ' failures'
   deallocate (msg, wrong)   ! main-program allocatables are not freed automatically (valgrind)
   if (failures /= 0) error stop 1

contains

   subroutine expect(got, want, message, what)
      integer(c_int), intent(in) :: got, want
      character(:), allocatable, intent(in) :: message
      character(*), intent(in) :: what
      checks = checks + 1
      if (got /= want) then
         failures = failures + 1
         write (error_unit, '(5a)') 'FAIL ', what, ': got ', rkmpm_status_string(got), ', expected '// &
            rkmpm_status_string(want)
         if (allocated(message)) write (error_unit, '(2a)') '     message: ', message
      else if (want /= RKMPM_OK) then
         if (.not. allocated(message)) then
            failures = failures + 1
            write (error_unit, '(3a)') 'FAIL ', what, ': errmsg not allocated'
         else if (len(message) == 0) then
            failures = failures + 1
            write (error_unit, '(3a)') 'FAIL ', what, ': empty errmsg'
         else
            write (output_unit, '(a, i2, 1x, a, a, a)') 'ok ', got, what, ': ', message
         end if
      end if
   end subroutine expect

   subroutine expect_true(condition, what)
      logical, intent(in) :: condition
      character(*), intent(in) :: what
      checks = checks + 1
      if (.not. condition) then
         failures = failures + 1
         write (error_unit, '(2a)') 'FAIL ', what
      end if
   end subroutine expect_true

end program error_handling
