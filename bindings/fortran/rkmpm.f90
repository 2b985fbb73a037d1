!> Fortran 2018 bindings of rkmpm, the embeddable Material Point Method engine.
!>
!> Two layers:
!>  - private raw `bind(C)` interfaces, one per C function of include/rkmpm.h, named as in C,
!>    each with its C prototype as a comment;
!>  - a public layer: the derived type `rkmpm_sim` with type-bound procedures, named constants for
!>    every enum value of the header, and a few library-level functions.
!>
!> Layout: vectors are stored dimension-fastest in C (x[p*dim + d]), which is x(dim, n) in Fortran
!> with no copy; tensors (stress, deformation gradient) are dim*dim values per particle in C's
!> row-major order, i.e. the transpose when read as a Fortran (dim, dim) matrix.
!>
!> Errors: every procedure that can fail takes optional `stat` (receives the RKMPM_* status) and
!> `errmsg` (receives the library's message). When `stat` is absent and the call fails, the
!> program stops with `error stop` and the message. On failure the simulation is unchanged.
!>
!> Lifetime: `call sim%init(...)` creates the simulation, `call sim%free()` releases it (and may
!> be called again, or on a never-initialized object). The type has no `final` procedure on
!> purpose: intrinsic assignment `b = a` copies the handle, and a finalizer would then release the
!> same simulation twice (or leave `b` dangling). Treat an rkmpm_sim like a file unit: one owner,
!> freed once; do not assign one rkmpm_sim to another.
!>
!> Queries (dim, time, step_count, stable_dt, field_len, boundary_point_count) are functions that
!> also take `stat` and `errmsg`, so they are impure: read them into variables before combining
!> them in `.and.`/`.or.` expressions, which gfortran may short-circuit (-Wfunction-elimination).
!>
!> Threads: one thread at a time per simulation; the library's error message is per thread.
module rkmpm
   use, intrinsic :: iso_c_binding, only: c_ptr, c_funptr, c_null_ptr, c_null_funptr, c_null_char, &
                                          c_char, c_int, c_int32_t, c_int64_t, c_size_t, c_double, &
                                          c_associated, c_f_pointer, c_funloc
   implicit none (type, external)
   private

   ! ---------------------------------------------------------------------------------------------
   ! Constants (same names and values as include/rkmpm.h)
   ! ---------------------------------------------------------------------------------------------

   !> The binary interface version these bindings were written for; compare it with
   !> rkmpm_library_abi_version(). (The C macro RKMPM_ABI_VERSION cannot keep its name in
   !> Fortran: names are case-insensitive and rkmpm_abi_version is the C function.)
   integer(c_int32_t), parameter, public :: RKMPM_BINDING_ABI_VERSION = 1
   ! The bound on the steps of one advance of a new (or loaded) simulation
   ! (sim%set_max_steps_per_advance changes it).
   integer(c_int64_t), parameter, public :: RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE = 1000000000
   ! The stopping rule of VC's solve of order 1 in a new simulation (sim%set_vc_solve changes
   ! it); at order >= 2 the automatic rule, 1e-4 falling as (32 / N)^3 on grids N > 32 cells
   ! across (sim%vc_solve reports the rule in force).
   real(c_double), parameter, public :: RKMPM_DEFAULT_VC_SOLVE_TOLERANCE = 1.0e-4_c_double
   integer(c_int64_t), parameter, public :: RKMPM_DEFAULT_VC_SOLVE_MAX_ITERATIONS = 2000
   ! Every how many steps VC's solve runs in a new simulation (sim%set_vc_solve_interval changes
   ! it): every step, but at order 1 RKMPM_BSPLINE_VC_SOLVE_INTERVAL steps with B-splines and
   ! RKMPM_RK_VC_SOLVE_INTERVAL with RK shape functions, the steps between taking the last
   ! solve's coefficients, on grids up to RKMPM_BSPLINE_VC_CARRIED_CELLS and
   ! RKMPM_RK_VC_CARRIED_CELLS cells along the widest axis, halved with every doubling beyond.
   integer(c_int32_t), parameter, public :: RKMPM_DEFAULT_VC_SOLVE_INTERVAL = 1
   integer(c_int32_t), parameter, public :: RKMPM_RK_VC_SOLVE_INTERVAL = 8
   integer(c_int32_t), parameter, public :: RKMPM_BSPLINE_VC_SOLVE_INTERVAL = 2
   integer(c_int64_t), parameter, public :: RKMPM_RK_VC_CARRIED_CELLS = 256
   integer(c_int64_t), parameter, public :: RKMPM_BSPLINE_VC_CARRIED_CELLS = 256
   ! Every how many steps VC finds the surface of the particles anew in a new simulation
   ! (sim%set_vc_surface_refresh changes it).
   integer(c_int32_t), parameter, public :: RKMPM_DEFAULT_VC_SURFACE_REFRESH = 4
   ! The most worker threads sim%set_threads starts for one simulation.
   integer(c_int32_t), parameter, public :: RKMPM_MAX_THREADS = 4096

   ! enum RkmpmStatus (a C enum: int-sized)
   integer(c_int), parameter, public :: RKMPM_OK = 0
   integer(c_int), parameter, public :: RKMPM_ERR_NULL_POINTER = 1
   integer(c_int), parameter, public :: RKMPM_ERR_INVALID_ARGUMENT = 2
   integer(c_int), parameter, public :: RKMPM_ERR_BUFFER_TOO_SMALL = 3
   integer(c_int), parameter, public :: RKMPM_ERR_INVALID_STATE = 4
   integer(c_int), parameter, public :: RKMPM_ERR_UNKNOWN_MATERIAL = 5
   integer(c_int), parameter, public :: RKMPM_ERR_OUTSIDE_GRID = 6
   integer(c_int), parameter, public :: RKMPM_ERR_UNSTABLE_TIME_STEP = 7
   integer(c_int), parameter, public :: RKMPM_ERR_NON_FINITE = 8
   integer(c_int), parameter, public :: RKMPM_ERR_INVERTED_PARTICLE = 9
   integer(c_int), parameter, public :: RKMPM_ERR_CALLBACK = 10
   integer(c_int), parameter, public :: RKMPM_ERR_IO = 11
   integer(c_int), parameter, public :: RKMPM_ERR_UNSUPPORTED = 12
   integer(c_int), parameter, public :: RKMPM_ERR_PANIC = 13
   integer(c_int), parameter, public :: RKMPM_ERR_CORRUPT_FILE = 14
   integer(c_int), parameter, public :: RKMPM_ERR_OUT_OF_MEMORY = 15

   ! RkmpmShape (uint32_t)
   integer(c_int32_t), parameter, public :: RKMPM_SHAPE_LINEAR = 0
   integer(c_int32_t), parameter, public :: RKMPM_SHAPE_BSPLINE2 = 1
   integer(c_int32_t), parameter, public :: RKMPM_SHAPE_BSPLINE3 = 2
   integer(c_int32_t), parameter, public :: RKMPM_SHAPE_RK = 3
   ! RkmpmIntegration (uint32_t)
   integer(c_int32_t), parameter, public :: RKMPM_INTEGRATION_MP = 0
   integer(c_int32_t), parameter, public :: RKMPM_INTEGRATION_VC = 1
   ! RkmpmTransfer (uint32_t)
   integer(c_int32_t), parameter, public :: RKMPM_TRANSFER_PIC_FLIP = 0
   integer(c_int32_t), parameter, public :: RKMPM_TRANSFER_APIC = 1
   integer(c_int32_t), parameter, public :: RKMPM_TRANSFER_MLS = 2
   ! RkmpmScheme (uint32_t)
   integer(c_int32_t), parameter, public :: RKMPM_SCHEME_USL = 0
   integer(c_int32_t), parameter, public :: RKMPM_SCHEME_MUSL = 1
   ! RkmpmVtkFormat (uint32_t)
   integer(c_int32_t), parameter, public :: RKMPM_VTK_BINARY = 0
   integer(c_int32_t), parameter, public :: RKMPM_VTK_ASCII = 1
   ! RkmpmBoundary (uint32_t)
   integer(c_int32_t), parameter, public :: RKMPM_BOUNDARY_FREE = 0
   integer(c_int32_t), parameter, public :: RKMPM_BOUNDARY_FIXED = 1
   integer(c_int32_t), parameter, public :: RKMPM_BOUNDARY_SLIP = 2
   integer(c_int32_t), parameter, public :: RKMPM_BOUNDARY_FRICTION = 3
   ! RkmpmField (uint32_t); values per particle in the comment
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_POSITION = 0              ! dim
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_VELOCITY = 1              ! dim
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_DISPLACEMENT = 2          ! dim
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_STRESS = 3                ! dim*dim, row-major
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_PRESSURE = 4              ! 1
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_VOLUME = 5                ! 1
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_MASS = 6                  ! 1
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_REFERENCE_POSITION = 7    ! dim
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_DEFORMATION_GRADIENT = 8  ! dim*dim, row-major
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_PLASTIC_STRAIN = 9        ! 1, equivalent plastic strain
   integer(c_int32_t), parameter, public :: RKMPM_FIELD_DAMAGE = 10               ! 1, damage in [0, 1]

   !> Johnson-Cook metal parameters (struct RkmpmJohnsonCook; SI units, kelvin). Set
   !> damage_enabled / eos_enabled to 1 to use d1..d5 / the Mie-Grueneisen eos_* values.
   type, bind(C), public :: rkmpm_johnson_cook
      real(c_double) :: density, young, poisson, a, b, n, c, reference_strain_rate, m
      real(c_double) :: room_temperature, melt_temperature, specific_heat, taylor_quinney
      integer(c_int32_t) :: damage_enabled = 0
      real(c_double) :: d1 = 0, d2 = 0, d3 = 0, d4 = 0, d5 = 0
      integer(c_int32_t) :: eos_enabled = 0
      real(c_double) :: eos_sound_speed = 0, eos_slope = 0, eos_gamma0 = 0
   end type rkmpm_johnson_cook

   !> The energies of the particles at one instant (struct RkmpmEnergies; per unit thickness in
   !> 2D): kinetic, stored (elastic) and the potential of the gravity set now. What a run
   !> dissipated (plasticity, damage, walls, contact, the scheme) is not among them.
   type, bind(C), public :: rkmpm_energies
      real(c_double) :: kinetic = 0, stored = 0, gravitational = 0
   end type rkmpm_energies

   !> Where a run's energy went since the accounting started (struct RkmpmEnergyBalance; per
   !> unit thickness in 2D): the energies now, the start (plus what the caller gave since), the
   !> external work (body-force callback, tractions), the stress work, what plasticity and
   !> damage dissipated, the work of friction at walls and in contact, and the rest (impacts'
   !> normal loss, the scheme), so that
   !> kinetic + stored + gravitational = start + external_work - material_dissipation
   !> - friction_dissipation - contact_dissipation - other_dissipation.
   type, bind(C), public :: rkmpm_energy_balance
      real(c_double) :: kinetic = 0, stored = 0, gravitational = 0, start = 0
      real(c_double) :: external_work = 0, stress_work = 0
      real(c_double) :: material_dissipation = 0, friction_dissipation = 0
      real(c_double) :: contact_dissipation = 0, other_dissipation = 0
   end type rkmpm_energy_balance

   !> The particles' linear momentum and angular momentum about the origin (struct
   !> RkmpmMomenta; third components 0, and in 2D only angular(3) not 0), the affine
   !> velocities' part included under APIC and MLS with a B-spline or RK1 with support 2.
   type, bind(C), public :: rkmpm_momenta
      real(c_double) :: linear(3) = 0, angular(3) = 0
   end type rkmpm_momenta

   ! Sides of a grid face (rkmpm_sim_set_boundary)
   integer(c_int32_t), parameter, public :: RKMPM_SIDE_LOW = -1
   integer(c_int32_t), parameter, public :: RKMPM_SIDE_HIGH = 1

   ! ---------------------------------------------------------------------------------------------
   ! The body-force callback
   ! ---------------------------------------------------------------------------------------------

   public :: rkmpm_body_force_fn
   abstract interface
      !> typedef int32_t (*RkmpmBodyForceFn)(void *user_data, double time, size_t count, uint32_t dim,
      !>     const double *reference_positions, const double *positions, double *accelerations);
      !>
      !> Body force per unit mass of every particle: write accelerations(:, p) and return 0; any
      !> other value fails the step with RKMPM_ERR_CALLBACK. Called once per step, on the thread
      !> that calls step, with the time at the start of the step. Write it as a `bind(C)`
      !> function with this interface; it must not call back into the simulation that is stepping.
      integer(c_int32_t) function rkmpm_body_force_fn(user_data, time, count, dim, reference_positions, &
                                                      positions, accelerations) bind(C)
         import :: c_ptr, c_double, c_size_t, c_int32_t
         type(c_ptr), value :: user_data
         real(c_double), value :: time
         integer(c_size_t), value :: count
         integer(c_int32_t), value :: dim
         real(c_double), intent(in) :: reference_positions(dim, count)
         real(c_double), intent(in) :: positions(dim, count)
         real(c_double), intent(inout) :: accelerations(dim, count)
      end function rkmpm_body_force_fn
   end interface

   public :: rkmpm_progress_fn
   abstract interface
      !> typedef int32_t (*RkmpmProgressFn)(void *user_data, uint64_t steps, double time,
      !>     double end_time, double dt);
      !>
      !> Progress of advance, called after each of its steps: return 0 to go on; any other value
      !> stops the run there with RKMPM_ERR_CALLBACK (the steps taken stand). It must not call
      !> back into the simulation that is advancing.
      integer(c_int32_t) function rkmpm_progress_fn(user_data, steps, time, end_time, dt) bind(C)
         import :: c_ptr, c_double, c_int64_t, c_int32_t
         type(c_ptr), value :: user_data
         integer(c_int64_t), value :: steps
         real(c_double), value :: time, end_time, dt
      end function rkmpm_progress_fn
   end interface

   ! ---------------------------------------------------------------------------------------------
   ! The simulation handle
   ! ---------------------------------------------------------------------------------------------

   !> A simulation. No `final` procedure: see the module comment (intrinsic assignment copies the
   !> handle). Create with init, release with free.
   type, public :: rkmpm_sim
      private
      type(c_ptr) :: h = c_null_ptr
   contains
      procedure :: init => sim_init
      procedure :: free => sim_free
      procedure :: is_initialized => sim_is_initialized
      procedure :: dim => sim_dim
      procedure :: set_shape => sim_set_shape
      procedure :: set_integration => sim_set_integration
      procedure :: set_transfer => sim_set_transfer
      procedure :: set_scheme => sim_set_scheme
      procedure :: set_gravity => sim_set_gravity
      procedure :: set_boundary => sim_set_boundary
      procedure :: set_body_force => sim_set_body_force
      procedure :: set_progress => sim_set_progress
      procedure :: add_material_linear_elastic => sim_add_material_linear_elastic
      procedure :: add_material_neo_hookean => sim_add_material_neo_hookean
      procedure :: add_material_drucker_prager => sim_add_material_drucker_prager
      procedure :: add_material_johnson_cook => sim_add_material_johnson_cook
      procedure :: add_material_rigid => sim_add_material_rigid
      procedure :: set_rigid_velocity => sim_set_rigid_velocity
      procedure :: set_contact => sim_set_contact
      procedure :: set_drucker_prager_rheology => sim_set_drucker_prager_rheology
      procedure :: save => sim_save
      procedure :: load => sim_load
      procedure :: add_particles => sim_add_particles
      procedure :: add_boundary_points => sim_add_boundary_points
      procedure :: boundary_point_count => sim_boundary_point_count
      procedure :: stable_dt => sim_stable_dt
      procedure :: step => sim_step
      procedure :: advance => sim_advance
      procedure :: set_max_steps_per_advance => sim_set_max_steps_per_advance
      procedure :: max_steps_per_advance => sim_max_steps_per_advance
      procedure :: set_vc_solve => sim_set_vc_solve
      procedure :: vc_solve => sim_vc_solve
      procedure :: set_vc_solve_interval => sim_set_vc_solve_interval
      procedure :: vc_solve_interval => sim_vc_solve_interval
      procedure :: set_vc_surface_refresh => sim_set_vc_surface_refresh
      procedure :: vc_surface_refresh => sim_vc_surface_refresh
      procedure :: set_threads => sim_set_threads
      procedure :: threads => sim_threads
      procedure :: time => sim_time
      procedure :: energies => sim_energies
      procedure :: momenta => sim_momenta
      procedure :: set_energy_accounting => sim_set_energy_accounting
      procedure :: energy_balance => sim_energy_balance
      procedure :: step_count => sim_step_count
      procedure :: particle_count => sim_particle_count
      procedure :: field_len => sim_field_len
      procedure, private :: sim_get_particles_1d
      procedure, private :: sim_get_particles_2d
      generic :: get_particles => sim_get_particles_1d, sim_get_particles_2d
      procedure :: set_vtk_format => sim_set_vtk_format
      procedure :: write_vtk => sim_write_vtk
      procedure :: write_vtk_frame => sim_write_vtk_frame
   end type rkmpm_sim

   public :: rkmpm_version_string, rkmpm_library_abi_version, rkmpm_status_string, rkmpm_last_error

   ! ---------------------------------------------------------------------------------------------
   ! Raw C interfaces (private)
   ! ---------------------------------------------------------------------------------------------

   interface
      ! const char *rkmpm_version(void);
      type(c_ptr) function rkmpm_version() bind(C, name="rkmpm_version")
         import :: c_ptr
      end function rkmpm_version

      ! uint32_t rkmpm_abi_version(void);
      integer(c_int32_t) function rkmpm_abi_version() bind(C, name="rkmpm_abi_version")
         import :: c_int32_t
      end function rkmpm_abi_version

      ! const char *rkmpm_status_str(int32_t status);
      type(c_ptr) function rkmpm_status_str(status) bind(C, name="rkmpm_status_str")
         import :: c_ptr, c_int32_t
         integer(c_int32_t), value :: status
      end function rkmpm_status_str

      ! size_t rkmpm_last_error_message(char *buf, size_t len);
      integer(c_size_t) function rkmpm_last_error_message(buf, len) bind(C, name="rkmpm_last_error_message")
         import :: c_size_t, c_char
         character(kind=c_char), intent(inout) :: buf(*)
         integer(c_size_t), value :: len
      end function rkmpm_last_error_message

      ! enum RkmpmStatus rkmpm_sim_new(uint32_t dim, const double *origin, const size_t *cells,
      !                                double cell_size, struct RkmpmSim **out);
      integer(c_int) function rkmpm_sim_new(dim, origin, cells, cell_size, out) bind(C, name="rkmpm_sim_new")
         import :: c_int, c_int32_t, c_double, c_size_t, c_ptr
         integer(c_int32_t), value :: dim
         real(c_double), intent(in) :: origin(*)
         integer(c_size_t), intent(in) :: cells(*)
         real(c_double), value :: cell_size
         type(c_ptr), intent(out) :: out
      end function rkmpm_sim_new

      ! void rkmpm_sim_free(struct RkmpmSim *sim);
      subroutine rkmpm_sim_free(sim) bind(C, name="rkmpm_sim_free")
         import :: c_ptr
         type(c_ptr), value :: sim
      end subroutine rkmpm_sim_free

      ! enum RkmpmStatus rkmpm_sim_dim(const struct RkmpmSim *sim, uint32_t *out_dim);
      integer(c_int) function rkmpm_sim_dim(sim, out_dim) bind(C, name="rkmpm_sim_dim")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), intent(out) :: out_dim
      end function rkmpm_sim_dim

      ! enum RkmpmStatus rkmpm_sim_set_shape(struct RkmpmSim *sim, RkmpmShape shape,
      !                                      uint32_t rk_order, double rk_support);
      integer(c_int) function rkmpm_sim_set_shape(sim, shape, rk_order, rk_support) &
         bind(C, name="rkmpm_sim_set_shape")
         import :: c_int, c_ptr, c_int32_t, c_double
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: shape
         integer(c_int32_t), value :: rk_order
         real(c_double), value :: rk_support
      end function rkmpm_sim_set_shape

      ! enum RkmpmStatus rkmpm_sim_set_integration(struct RkmpmSim *sim,
      !                                            RkmpmIntegration integration, uint32_t vc_order);
      integer(c_int) function rkmpm_sim_set_integration(sim, integration, vc_order) &
         bind(C, name="rkmpm_sim_set_integration")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: integration
         integer(c_int32_t), value :: vc_order
      end function rkmpm_sim_set_integration

      ! enum RkmpmStatus rkmpm_sim_set_transfer(struct RkmpmSim *sim, RkmpmTransfer transfer,
      !                                         double flip_ratio);
      integer(c_int) function rkmpm_sim_set_transfer(sim, transfer, flip_ratio) &
         bind(C, name="rkmpm_sim_set_transfer")
         import :: c_int, c_ptr, c_int32_t, c_double
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: transfer
         real(c_double), value :: flip_ratio
      end function rkmpm_sim_set_transfer

      ! enum RkmpmStatus rkmpm_sim_set_scheme(struct RkmpmSim *sim, RkmpmScheme scheme);
      integer(c_int) function rkmpm_sim_set_scheme(sim, scheme) bind(C, name="rkmpm_sim_set_scheme")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: scheme
      end function rkmpm_sim_set_scheme

      ! enum RkmpmStatus rkmpm_sim_set_gravity(struct RkmpmSim *sim, const double *g);
      integer(c_int) function rkmpm_sim_set_gravity(sim, g) bind(C, name="rkmpm_sim_set_gravity")
         import :: c_int, c_ptr, c_double
         type(c_ptr), value :: sim
         real(c_double), intent(in) :: g(*)
      end function rkmpm_sim_set_gravity

      ! enum RkmpmStatus rkmpm_sim_set_boundary(struct RkmpmSim *sim, uint32_t axis, int32_t side,
      !                                         RkmpmBoundary kind, double friction);
      integer(c_int) function rkmpm_sim_set_boundary(sim, axis, side, kind, friction) &
         bind(C, name="rkmpm_sim_set_boundary")
         import :: c_int, c_ptr, c_int32_t, c_double
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: axis
         integer(c_int32_t), value :: side
         integer(c_int32_t), value :: kind
         real(c_double), value :: friction
      end function rkmpm_sim_set_boundary

      ! enum RkmpmStatus rkmpm_sim_set_body_force(struct RkmpmSim *sim, RkmpmBodyForceFn f,
      !                                           void *user_data);
      integer(c_int) function rkmpm_sim_set_body_force(sim, f, user_data) &
         bind(C, name="rkmpm_sim_set_body_force")
         import :: c_int, c_ptr, c_funptr
         type(c_ptr), value :: sim
         type(c_funptr), value :: f
         type(c_ptr), value :: user_data
      end function rkmpm_sim_set_body_force

      ! enum RkmpmStatus rkmpm_sim_set_progress(struct RkmpmSim *sim, RkmpmProgressFn f,
      !                                         void *user_data);
      integer(c_int) function rkmpm_sim_set_progress(sim, f, user_data) &
         bind(C, name="rkmpm_sim_set_progress")
         import :: c_int, c_ptr, c_funptr
         type(c_ptr), value :: sim
         type(c_funptr), value :: f
         type(c_ptr), value :: user_data
      end function rkmpm_sim_set_progress

      ! enum RkmpmStatus rkmpm_sim_add_material_linear_elastic(struct RkmpmSim *sim, double density,
      !                                                        double young, double poisson,
      !                                                        uint32_t *out_id);
      integer(c_int) function rkmpm_sim_add_material_linear_elastic(sim, density, young, poisson, out_id) &
         bind(C, name="rkmpm_sim_add_material_linear_elastic")
         import :: c_int, c_ptr, c_double, c_int32_t
         type(c_ptr), value :: sim
         real(c_double), value :: density
         real(c_double), value :: young
         real(c_double), value :: poisson
         integer(c_int32_t), intent(out) :: out_id
      end function rkmpm_sim_add_material_linear_elastic

      ! enum RkmpmStatus rkmpm_sim_add_material_neo_hookean(struct RkmpmSim *sim, double density,
      !                                                     double young, double poisson,
      !                                                     uint32_t *out_id);
      integer(c_int) function rkmpm_sim_add_material_neo_hookean(sim, density, young, poisson, out_id) &
         bind(C, name="rkmpm_sim_add_material_neo_hookean")
         import :: c_int, c_ptr, c_double, c_int32_t
         type(c_ptr), value :: sim
         real(c_double), value :: density
         real(c_double), value :: young
         real(c_double), value :: poisson
         integer(c_int32_t), intent(out) :: out_id
      end function rkmpm_sim_add_material_neo_hookean

      ! enum RkmpmStatus rkmpm_sim_add_material_drucker_prager(struct RkmpmSim *sim, double density,
      !     double young, double poisson, double friction_angle, double cohesion,
      !     double dilatancy_angle, uint32_t *out_id);   /* angles in degrees */
      integer(c_int) function rkmpm_sim_add_material_drucker_prager(sim, density, young, poisson, &
            friction_angle, cohesion, dilatancy_angle, out_id) &
         bind(C, name="rkmpm_sim_add_material_drucker_prager")
         import :: c_int, c_ptr, c_double, c_int32_t
         type(c_ptr), value :: sim
         real(c_double), value :: density
         real(c_double), value :: young
         real(c_double), value :: poisson
         real(c_double), value :: friction_angle
         real(c_double), value :: cohesion
         real(c_double), value :: dilatancy_angle
         integer(c_int32_t), intent(out) :: out_id
      end function rkmpm_sim_add_material_drucker_prager

      ! enum RkmpmStatus rkmpm_sim_add_material_johnson_cook(struct RkmpmSim *sim,
      !     const struct RkmpmJohnsonCook *parameters, uint32_t *out_id);
      integer(c_int) function rkmpm_sim_add_material_johnson_cook(sim, parameters, out_id) &
         bind(C, name="rkmpm_sim_add_material_johnson_cook")
         import :: c_int, c_ptr, c_int32_t, rkmpm_johnson_cook
         type(c_ptr), value :: sim
         type(rkmpm_johnson_cook), intent(in) :: parameters
         integer(c_int32_t), intent(out) :: out_id
      end function rkmpm_sim_add_material_johnson_cook

      ! enum RkmpmStatus rkmpm_sim_add_material_rigid(struct RkmpmSim *sim, double density,
      !                                              const double *velocity, uint32_t *out_id);
      integer(c_int) function rkmpm_sim_add_material_rigid(sim, density, velocity, out_id) &
         bind(C, name="rkmpm_sim_add_material_rigid")
         import :: c_int, c_ptr, c_double, c_int32_t
         type(c_ptr), value :: sim
         real(c_double), value :: density
         real(c_double), intent(in) :: velocity(*)
         integer(c_int32_t), intent(out) :: out_id
      end function rkmpm_sim_add_material_rigid

      ! enum RkmpmStatus rkmpm_sim_set_rigid_velocity(struct RkmpmSim *sim, uint32_t material,
      !                                              const double *velocity);
      integer(c_int) function rkmpm_sim_set_rigid_velocity(sim, material, velocity) &
         bind(C, name="rkmpm_sim_set_rigid_velocity")
         import :: c_int, c_ptr, c_double, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: material
         real(c_double), intent(in) :: velocity(*)
      end function rkmpm_sim_set_rigid_velocity

      ! enum RkmpmStatus rkmpm_sim_set_contact(struct RkmpmSim *sim, uint32_t enabled, double friction);
      integer(c_int) function rkmpm_sim_set_contact(sim, enabled, friction) &
         bind(C, name="rkmpm_sim_set_contact")
         import :: c_int, c_ptr, c_double, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: enabled
         real(c_double), value :: friction
      end function rkmpm_sim_set_contact

      ! enum RkmpmStatus rkmpm_sim_set_drucker_prager_rheology(struct RkmpmSim *sim, uint32_t material,
      !     uint32_t enabled, double friction_increase, double reference_inertial_number,
      !     double grain_diameter);
      integer(c_int) function rkmpm_sim_set_drucker_prager_rheology(sim, material, enabled, &
            friction_increase, reference_inertial_number, grain_diameter) &
         bind(C, name="rkmpm_sim_set_drucker_prager_rheology")
         import :: c_int, c_ptr, c_double, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: material
         integer(c_int32_t), value :: enabled
         real(c_double), value :: friction_increase
         real(c_double), value :: reference_inertial_number
         real(c_double), value :: grain_diameter
      end function rkmpm_sim_set_drucker_prager_rheology

      ! enum RkmpmStatus rkmpm_sim_add_particles(struct RkmpmSim *sim, uint32_t material, size_t count,
      !                                          const double *positions, const double *volumes,
      !                                          const double *velocities);   /* velocities may be NULL */
      integer(c_int) function rkmpm_sim_add_particles(sim, material, count, positions, volumes, velocities) &
         bind(C, name="rkmpm_sim_add_particles")
         import :: c_int, c_ptr, c_int32_t, c_size_t, c_double
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: material
         integer(c_size_t), value :: count
         real(c_double), intent(in) :: positions(*)
         real(c_double), intent(in) :: volumes(*)
         real(c_double), intent(in), optional :: velocities(*)   ! absent -> NULL
      end function rkmpm_sim_add_particles

      ! enum RkmpmStatus rkmpm_sim_add_boundary_points(struct RkmpmSim *sim, size_t count,
      !                                                const double *positions, const double *area_normals,
      !                                                const double *tractions);   /* tractions may be NULL */
      integer(c_int) function rkmpm_sim_add_boundary_points(sim, count, positions, area_normals, tractions) &
         bind(C, name="rkmpm_sim_add_boundary_points")
         import :: c_int, c_ptr, c_size_t, c_double
         type(c_ptr), value :: sim
         integer(c_size_t), value :: count
         real(c_double), intent(in) :: positions(*)
         real(c_double), intent(in) :: area_normals(*)
         real(c_double), intent(in), optional :: tractions(*)   ! absent -> NULL
      end function rkmpm_sim_add_boundary_points

      ! enum RkmpmStatus rkmpm_sim_boundary_point_count(const struct RkmpmSim *sim, size_t *out_count);
      integer(c_int) function rkmpm_sim_boundary_point_count(sim, out_count) &
         bind(C, name="rkmpm_sim_boundary_point_count")
         import :: c_int, c_ptr, c_size_t
         type(c_ptr), value :: sim
         integer(c_size_t), intent(out) :: out_count
      end function rkmpm_sim_boundary_point_count

      ! enum RkmpmStatus rkmpm_sim_stable_dt(const struct RkmpmSim *sim, double cfl, double *out_dt);
      integer(c_int) function rkmpm_sim_stable_dt(sim, cfl, out_dt) bind(C, name="rkmpm_sim_stable_dt")
         import :: c_int, c_ptr, c_double
         type(c_ptr), value :: sim
         real(c_double), value :: cfl
         real(c_double), intent(out) :: out_dt
      end function rkmpm_sim_stable_dt

      ! enum RkmpmStatus rkmpm_sim_step(struct RkmpmSim *sim, double dt);
      integer(c_int) function rkmpm_sim_step(sim, dt) bind(C, name="rkmpm_sim_step")
         import :: c_int, c_ptr, c_double
         type(c_ptr), value :: sim
         real(c_double), value :: dt
      end function rkmpm_sim_step

      ! enum RkmpmStatus rkmpm_sim_advance(struct RkmpmSim *sim, double duration, double cfl,
      !                                    uint64_t *out_steps);
      integer(c_int) function rkmpm_sim_advance(sim, duration, cfl, out_steps) &
            bind(C, name="rkmpm_sim_advance")
         import :: c_int, c_ptr, c_double, c_int64_t
         type(c_ptr), value :: sim
         real(c_double), value :: duration, cfl
         integer(c_int64_t), intent(out) :: out_steps
      end function rkmpm_sim_advance

      ! enum RkmpmStatus rkmpm_sim_set_max_steps_per_advance(struct RkmpmSim *sim,
      !                                                    uint64_t max_steps);
      integer(c_int) function rkmpm_sim_set_max_steps_per_advance(sim, max_steps) &
            bind(C, name="rkmpm_sim_set_max_steps_per_advance")
         import :: c_int, c_ptr, c_int64_t
         type(c_ptr), value :: sim
         integer(c_int64_t), value :: max_steps
      end function rkmpm_sim_set_max_steps_per_advance

      ! enum RkmpmStatus rkmpm_sim_max_steps_per_advance(const struct RkmpmSim *sim,
      !                                                uint64_t *out_max_steps);
      integer(c_int) function rkmpm_sim_max_steps_per_advance(sim, out_max_steps) &
            bind(C, name="rkmpm_sim_max_steps_per_advance")
         import :: c_int, c_ptr, c_int64_t
         type(c_ptr), value :: sim
         integer(c_int64_t), intent(out) :: out_max_steps
      end function rkmpm_sim_max_steps_per_advance

      ! enum RkmpmStatus rkmpm_sim_set_vc_solve(struct RkmpmSim *sim, double tolerance,
      !                                         uint64_t max_iterations);
      integer(c_int) function rkmpm_sim_set_vc_solve(sim, tolerance, max_iterations) &
            bind(C, name="rkmpm_sim_set_vc_solve")
         import :: c_int, c_ptr, c_double, c_int64_t
         type(c_ptr), value :: sim
         real(c_double), value :: tolerance
         integer(c_int64_t), value :: max_iterations
      end function rkmpm_sim_set_vc_solve

      ! enum RkmpmStatus rkmpm_sim_vc_solve(const struct RkmpmSim *sim, double *out_tolerance,
      !                                     uint64_t *out_max_iterations);
      integer(c_int) function rkmpm_sim_vc_solve(sim, out_tolerance, out_max_iterations) &
            bind(C, name="rkmpm_sim_vc_solve")
         import :: c_int, c_ptr, c_double, c_int64_t
         type(c_ptr), value :: sim
         real(c_double), intent(out) :: out_tolerance
         integer(c_int64_t), intent(out) :: out_max_iterations
      end function rkmpm_sim_vc_solve

      ! enum RkmpmStatus rkmpm_sim_set_vc_solve_interval(struct RkmpmSim *sim, uint32_t steps);
      integer(c_int) function rkmpm_sim_set_vc_solve_interval(sim, steps) &
            bind(C, name="rkmpm_sim_set_vc_solve_interval")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: steps
      end function rkmpm_sim_set_vc_solve_interval

      ! enum RkmpmStatus rkmpm_sim_vc_solve_interval(const struct RkmpmSim *sim,
      !                                              uint32_t *out_steps);
      integer(c_int) function rkmpm_sim_vc_solve_interval(sim, out_steps) &
            bind(C, name="rkmpm_sim_vc_solve_interval")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), intent(out) :: out_steps
      end function rkmpm_sim_vc_solve_interval

      ! enum RkmpmStatus rkmpm_sim_set_vc_surface_refresh(struct RkmpmSim *sim, uint32_t steps);
      integer(c_int) function rkmpm_sim_set_vc_surface_refresh(sim, steps) &
            bind(C, name="rkmpm_sim_set_vc_surface_refresh")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: steps
      end function rkmpm_sim_set_vc_surface_refresh

      ! enum RkmpmStatus rkmpm_sim_vc_surface_refresh(const struct RkmpmSim *sim,
      !                                               uint32_t *out_steps);
      integer(c_int) function rkmpm_sim_vc_surface_refresh(sim, out_steps) &
            bind(C, name="rkmpm_sim_vc_surface_refresh")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), intent(out) :: out_steps
      end function rkmpm_sim_vc_surface_refresh

      ! enum RkmpmStatus rkmpm_sim_set_threads(struct RkmpmSim *sim, uint32_t threads);
      integer(c_int) function rkmpm_sim_set_threads(sim, threads) &
            bind(C, name="rkmpm_sim_set_threads")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: threads
      end function rkmpm_sim_set_threads

      ! enum RkmpmStatus rkmpm_sim_threads(const struct RkmpmSim *sim, uint32_t *out_threads);
      integer(c_int) function rkmpm_sim_threads(sim, out_threads) &
            bind(C, name="rkmpm_sim_threads")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), intent(out) :: out_threads
      end function rkmpm_sim_threads

      ! enum RkmpmStatus rkmpm_sim_time(const struct RkmpmSim *sim, double *out_time);
      integer(c_int) function rkmpm_sim_time(sim, out_time) bind(C, name="rkmpm_sim_time")
         import :: c_int, c_ptr, c_double
         type(c_ptr), value :: sim
         real(c_double), intent(out) :: out_time
      end function rkmpm_sim_time

      ! enum RkmpmStatus rkmpm_sim_energies(const struct RkmpmSim *sim, struct RkmpmEnergies *out);
      integer(c_int) function rkmpm_sim_energies(sim, out) bind(C, name="rkmpm_sim_energies")
         import :: c_int, c_ptr, rkmpm_energies
         type(c_ptr), value :: sim
         type(rkmpm_energies), intent(out) :: out
      end function rkmpm_sim_energies

      ! enum RkmpmStatus rkmpm_sim_set_energy_accounting(struct RkmpmSim *sim, uint32_t on);
      integer(c_int) function rkmpm_sim_set_energy_accounting(sim, on) &
            bind(C, name="rkmpm_sim_set_energy_accounting")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: on
      end function rkmpm_sim_set_energy_accounting

      ! enum RkmpmStatus rkmpm_sim_energy_balance(const struct RkmpmSim *sim,
      !                                           struct RkmpmEnergyBalance *out);
      integer(c_int) function rkmpm_sim_energy_balance(sim, out) &
            bind(C, name="rkmpm_sim_energy_balance")
         import :: c_int, c_ptr, rkmpm_energy_balance
         type(c_ptr), value :: sim
         type(rkmpm_energy_balance), intent(out) :: out
      end function rkmpm_sim_energy_balance

      ! enum RkmpmStatus rkmpm_sim_momenta(const struct RkmpmSim *sim, struct RkmpmMomenta *out);
      integer(c_int) function rkmpm_sim_momenta(sim, out) bind(C, name="rkmpm_sim_momenta")
         import :: c_int, c_ptr, rkmpm_momenta
         type(c_ptr), value :: sim
         type(rkmpm_momenta), intent(out) :: out
      end function rkmpm_sim_momenta

      ! enum RkmpmStatus rkmpm_sim_step_count(const struct RkmpmSim *sim, uint64_t *out_steps);
      integer(c_int) function rkmpm_sim_step_count(sim, out_steps) bind(C, name="rkmpm_sim_step_count")
         import :: c_int, c_ptr, c_int64_t
         type(c_ptr), value :: sim
         integer(c_int64_t), intent(out) :: out_steps
      end function rkmpm_sim_step_count

      ! size_t rkmpm_sim_particle_count(const struct RkmpmSim *sim);
      integer(c_size_t) function rkmpm_sim_particle_count(sim) bind(C, name="rkmpm_sim_particle_count")
         import :: c_size_t, c_ptr
         type(c_ptr), value :: sim
      end function rkmpm_sim_particle_count

      ! enum RkmpmStatus rkmpm_sim_field_len(const struct RkmpmSim *sim, RkmpmField field,
      !                                      size_t *out_len);
      integer(c_int) function rkmpm_sim_field_len(sim, field, out_len) bind(C, name="rkmpm_sim_field_len")
         import :: c_int, c_ptr, c_int32_t, c_size_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: field
         integer(c_size_t), intent(out) :: out_len
      end function rkmpm_sim_field_len

      ! enum RkmpmStatus rkmpm_sim_get_particles(const struct RkmpmSim *sim, RkmpmField field,
      !                                          double *out, size_t len);
      integer(c_int) function rkmpm_sim_get_particles(sim, field, out, len) &
         bind(C, name="rkmpm_sim_get_particles")
         import :: c_int, c_ptr, c_int32_t, c_double, c_size_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: field
         real(c_double), intent(inout) :: out(*)   ! inout: on failure nothing is written
         integer(c_size_t), value :: len
      end function rkmpm_sim_get_particles

      ! enum RkmpmStatus rkmpm_sim_save(const struct RkmpmSim *sim, const char *path);
      integer(c_int) function rkmpm_sim_save(sim, path) bind(C, name="rkmpm_sim_save")
         import :: c_int, c_ptr, c_char
         type(c_ptr), value :: sim
         character(kind=c_char), intent(in) :: path(*)
      end function rkmpm_sim_save

      ! enum RkmpmStatus rkmpm_sim_load(const char *path, struct RkmpmSim **out);
      integer(c_int) function rkmpm_sim_load(path, out) bind(C, name="rkmpm_sim_load")
         import :: c_int, c_ptr, c_char
         character(kind=c_char), intent(in) :: path(*)
         type(c_ptr), intent(out) :: out
      end function rkmpm_sim_load

      ! enum RkmpmStatus rkmpm_sim_set_vtk_format(struct RkmpmSim *sim, RkmpmVtkFormat format);
      integer(c_int) function rkmpm_sim_set_vtk_format(sim, format) &
            bind(C, name="rkmpm_sim_set_vtk_format")
         import :: c_int, c_ptr, c_int32_t
         type(c_ptr), value :: sim
         integer(c_int32_t), value :: format
      end function rkmpm_sim_set_vtk_format

      ! enum RkmpmStatus rkmpm_sim_write_vtk(const struct RkmpmSim *sim, const char *path);
      integer(c_int) function rkmpm_sim_write_vtk(sim, path) bind(C, name="rkmpm_sim_write_vtk")
         import :: c_int, c_ptr, c_char
         type(c_ptr), value :: sim
         character(kind=c_char), intent(in) :: path(*)
      end function rkmpm_sim_write_vtk

      ! enum RkmpmStatus rkmpm_sim_write_vtk_frame(struct RkmpmSim *sim, const char *prefix);
      integer(c_int) function rkmpm_sim_write_vtk_frame(sim, prefix) bind(C, name="rkmpm_sim_write_vtk_frame")
         import :: c_int, c_ptr, c_char
         type(c_ptr), value :: sim
         character(kind=c_char), intent(in) :: prefix(*)
      end function rkmpm_sim_write_vtk_frame

      ! size_t strlen(const char *s);   (C library, to read the static strings above)
      integer(c_size_t) function c_strlen(s) bind(C, name="strlen")
         import :: c_size_t, c_ptr
         type(c_ptr), value :: s
      end function c_strlen
   end interface

contains

   ! ---------------------------------------------------------------------------------------------
   ! Library-level functions
   ! ---------------------------------------------------------------------------------------------

   !> A copy of a NUL-terminated C string (empty for NULL).
   function c_string(p) result(s)
      type(c_ptr), intent(in) :: p
      character(:), allocatable :: s
      character(kind=c_char), pointer :: chars(:)
      integer(c_size_t) :: n, i
      if (.not. c_associated(p)) then
         s = ''
         return
      end if
      n = c_strlen(p)
      call c_f_pointer(p, chars, [n])
      allocate (character(len=n) :: s)
      do i = 1, n
         s(i:i) = chars(i)
      end do
   end function c_string

   !> The library version, e.g. "0.1.0".
   function rkmpm_version_string() result(version)
      character(:), allocatable :: version
      version = c_string(rkmpm_version())
   end function rkmpm_version_string

   !> The binary interface version of the linked library; it must equal RKMPM_BINDING_ABI_VERSION.
   integer(c_int32_t) function rkmpm_library_abi_version()
      rkmpm_library_abi_version = rkmpm_abi_version()
   end function rkmpm_library_abi_version

   !> A short description of a status code ("unknown status" for a number that is none).
   function rkmpm_status_string(status) result(text)
      integer(c_int), intent(in) :: status
      character(:), allocatable :: text
      text = c_string(rkmpm_status_str(int(status, c_int32_t)))
   end function rkmpm_status_string

   !> The message of the last failed rkmpm call on this thread ('' if none failed).
   function rkmpm_last_error() result(message)
      character(:), allocatable :: message
      character(kind=c_char) :: probe(1)
      character(kind=c_char), allocatable :: buf(:)
      integer(c_size_t) :: n, i
      probe(1) = c_null_char
      n = rkmpm_last_error_message(probe, 1_c_size_t)   ! writes only the NUL, returns the length
      allocate (buf(n + 1))
      n = min(n, rkmpm_last_error_message(buf, n + 1))
      allocate (character(len=n) :: message)
      do i = 1, n
         message(i:i) = buf(i)
      end do
   end function rkmpm_last_error

   !> Reports `status`: sets `stat` when present and `text` to the message ('' on success); on
   !> failure without `stat`, stops. `message` replaces the library's message for failures found
   !> in these bindings.
   !> (Callers copy `text` into their own optional `errmsg`: passing an optional deferred-length
   !> dummy straight through to another procedure loses its length in gfortran 12.)
   subroutine report(status, what, stat, text, message)
      integer(c_int), intent(in) :: status
      character(*), intent(in) :: what
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out) :: text
      character(*), intent(in), optional :: message
      if (present(stat)) stat = status
      if (status == RKMPM_OK) then
         text = ''
         return
      end if
      if (present(message)) then
         text = what//': '//message
      else
         text = rkmpm_last_error()
         if (len(text) == 0) text = what//': '//rkmpm_status_string(status)
      end if
      if (.not. present(stat)) error stop 'rkmpm: '//text
   end subroutine report

   !> The dimension of a live handle (0 when the handle is not live).
   integer(c_int32_t) function handle_dim(h)
      type(c_ptr), intent(in) :: h
      integer(c_int32_t) :: d
      handle_dim = 0
      if (.not. c_associated(h)) return
      if (rkmpm_sim_dim(h, d) == RKMPM_OK) handle_dim = d
   end function handle_dim

   ! ---------------------------------------------------------------------------------------------
   ! rkmpm_sim
   ! ---------------------------------------------------------------------------------------------

   !> Creates a simulation on a uniform grid: dim = size(origin) (2 or 3), `cells` cell counts per
   !> axis (size dim), `cell_size` > 0. Fails with RKMPM_ERR_INVALID_STATE if `self` already holds
   !> a simulation (free it first).
   subroutine sim_init(self, origin, cells, cell_size, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: origin(:)
      integer, intent(in) :: cells(:)
      real(c_double), intent(in) :: cell_size
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_size_t), allocatable :: c_cells(:)
      real(c_double), allocatable :: c_origin(:)
      type(c_ptr) :: h
      integer(c_int) :: status
      if (c_associated(self%h)) then
         call report(RKMPM_ERR_INVALID_STATE, 'init', stat, text, &
                     'this rkmpm_sim already holds a simulation; call free first')
         if (present(errmsg)) errmsg = text
         return
      end if
      if (size(cells) /= size(origin)) then
         call report(RKMPM_ERR_INVALID_ARGUMENT, 'init', stat, text, &
                     'origin and cells must have the same size (the dimension)')
         if (present(errmsg)) errmsg = text
         return
      end if
      if (any(cells < 0)) then
         call report(RKMPM_ERR_INVALID_ARGUMENT, 'init', stat, text, 'cell counts must not be negative')
         if (present(errmsg)) errmsg = text
         return
      end if
      ! Copies so that a zero-size dummy still passes valid storage (dim 0 is an error in C).
      allocate (c_cells(max(size(cells), 1)), c_origin(max(size(origin), 1)))
      c_cells = 0
      c_origin = 0
      c_cells(1:size(cells)) = int(cells, c_size_t)
      c_origin(1:size(origin)) = origin
      status = rkmpm_sim_new(int(size(origin), c_int32_t), c_origin, c_cells, cell_size, h)
      if (status == RKMPM_OK) self%h = h
      call report(status, 'init', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_init

   !> Releases the simulation; safe to call more than once and on a never-initialized object.
   subroutine sim_free(self)
      class(rkmpm_sim), intent(inout) :: self
      call rkmpm_sim_free(self%h)
      self%h = c_null_ptr
   end subroutine sim_free

   !> Whether the object holds a simulation.
   logical function sim_is_initialized(self)
      class(rkmpm_sim), intent(in) :: self
      sim_is_initialized = c_associated(self%h)
   end function sim_is_initialized

   !> The dimension (2 or 3).
   integer(c_int32_t) function sim_dim(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: d
      d = 0
      call report(rkmpm_sim_dim(self%h, d), 'dim', stat, text)
      if (present(errmsg)) errmsg = text
      sim_dim = d
   end function sim_dim

   !> Chooses the shape function (before the first step); `rk_order` (1..5) and `rk_support` (in
   !> cells: about 2 for order 1, 3 for order 2) are read for RKMPM_SHAPE_RK only (defaults 1 and 2).
   !> A support too small for the order is refused (RKMPM_ERR_INVALID_ARGUMENT); RK of order >= 2
   !> needs RKMPM_TRANSFER_PIC_FLIP (with APIC the first step fails with RKMPM_ERR_UNSUPPORTED).
   subroutine sim_set_shape(self, shape, rk_order, rk_support, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: shape
      integer(c_int32_t), intent(in), optional :: rk_order
      real(c_double), intent(in), optional :: rk_support
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: order
      real(c_double) :: support
      order = 1
      support = 2
      if (present(rk_order)) order = rk_order
      if (present(rk_support)) support = rk_support
      call report(rkmpm_sim_set_shape(self%h, shape, order, support), 'set_shape', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_shape

   !> Chooses the integration (before the first step); `vc_order` (1..4, default 1) for VC only.
   !> VC uses the boundary points (add_boundary_points); without any, it finds the surface of the
   !> particles afresh at every step.
   subroutine sim_set_integration(self, integration, vc_order, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: integration
      integer(c_int32_t), intent(in), optional :: vc_order
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: order
      order = 1
      if (present(vc_order)) order = vc_order
      call report(rkmpm_sim_set_integration(self%h, integration, order), 'set_integration', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_integration

   !> Chooses the velocity transfer (before the first step); `flip_ratio` in [0, 1] (default 0,
   !> pure PIC) is read for RKMPM_TRANSFER_PIC_FLIP only.
   subroutine sim_set_transfer(self, transfer, flip_ratio, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: transfer
      real(c_double), intent(in), optional :: flip_ratio
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      real(c_double) :: flip
      flip = 0
      if (present(flip_ratio)) flip = flip_ratio
      call report(rkmpm_sim_set_transfer(self%h, transfer, flip), 'set_transfer', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_transfer

   !> Chooses USL or MUSL (before the first step).
   subroutine sim_set_scheme(self, scheme, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: scheme
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_set_scheme(self%h, scheme), 'set_scheme', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_scheme

   !> Sets gravity, size(g) == dim finite values.
   subroutine sim_set_gravity(self, g, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: g(:)
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      real(c_double) :: gc(3)
      if (c_associated(self%h)) then
         if (size(g) /= handle_dim(self%h)) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'set_gravity', stat, text, 'size(g) must equal the dimension')
            if (present(errmsg)) errmsg = text
            return
         end if
      end if
      gc = 0
      gc(1:min(size(g), 3)) = g(1:min(size(g), 3))
      call report(rkmpm_sim_set_gravity(self%h, gc), 'set_gravity', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_gravity

   !> Sets the condition on the face `side` (RKMPM_SIDE_LOW = -1 or RKMPM_SIDE_HIGH = +1) of
   !> `axis` (0-based as in C: 0 .. dim-1); `friction` (default 0) for RKMPM_BOUNDARY_FRICTION.
   subroutine sim_set_boundary(self, axis, side, kind, friction, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: axis
      integer(c_int32_t), intent(in) :: side
      integer(c_int32_t), intent(in) :: kind
      real(c_double), intent(in), optional :: friction
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      real(c_double) :: mu
      if (axis < 0) then
         call report(RKMPM_ERR_INVALID_ARGUMENT, 'set_boundary', stat, text, 'axis must not be negative')
         if (present(errmsg)) errmsg = text
         return
      end if
      mu = 0
      if (present(friction)) mu = friction
      call report(rkmpm_sim_set_boundary(self%h, axis, side, kind, mu), 'set_boundary', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_boundary

   !> Sets the body-force callback `f` (a bind(C) function with the interface
   !> rkmpm_body_force_fn) and its `user_data` (default C NULL, e.g. c_loc of a target variable
   !> that lives while the callback is set). Without `f`, removes the callback.
   subroutine sim_set_body_force(self, f, user_data, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      procedure(rkmpm_body_force_fn), optional :: f
      type(c_ptr), intent(in), optional :: user_data
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      type(c_funptr) :: fp
      type(c_ptr) :: ud
      fp = c_null_funptr
      ud = c_null_ptr
      if (present(f)) fp = c_funloc(f)
      if (present(user_data)) ud = user_data
      call report(rkmpm_sim_set_body_force(self%h, fp, ud), 'set_body_force', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_body_force

   !> Sets the progress callback of advance `f` (a bind(C) function with the interface
   !> rkmpm_progress_fn) and its `user_data`. Without `f`, removes the callback.
   subroutine sim_set_progress(self, f, user_data, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      procedure(rkmpm_progress_fn), optional :: f
      type(c_ptr), intent(in), optional :: user_data
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      type(c_funptr) :: fp
      type(c_ptr) :: ud
      fp = c_null_funptr
      ud = c_null_ptr
      if (present(f)) fp = c_funloc(f)
      if (present(user_data)) ud = user_data
      call report(rkmpm_sim_set_progress(self%h, fp, ud), 'set_progress', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_progress

   !> Adds a small-strain linear elastic material; `id` receives its id (for add_particles).
   subroutine sim_add_material_linear_elastic(self, density, young, poisson, id, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: density, young, poisson
      integer(c_int32_t), intent(out) :: id
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: out_id
      out_id = -1
      call report(rkmpm_sim_add_material_linear_elastic(self%h, density, young, poisson, out_id), &
                  'add_material_linear_elastic', stat, text)
      if (present(errmsg)) errmsg = text
      id = out_id
   end subroutine sim_add_material_linear_elastic

   !> Adds a compressible neo-Hookean material; `id` receives its id.
   subroutine sim_add_material_neo_hookean(self, density, young, poisson, id, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: density, young, poisson
      integer(c_int32_t), intent(out) :: id
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: out_id
      out_id = -1
      call report(rkmpm_sim_add_material_neo_hookean(self%h, density, young, poisson, out_id), &
                  'add_material_neo_hookean', stat, text)
      if (present(errmsg)) errmsg = text
      id = out_id
   end subroutine sim_add_material_neo_hookean

   !> Adds a Drucker-Prager soil (angles in degrees, cohesion in Pa); see the C header.
   subroutine sim_add_material_drucker_prager(self, density, young, poisson, friction_angle, &
                                              cohesion, dilatancy_angle, id, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: density, young, poisson, friction_angle, cohesion, dilatancy_angle
      integer(c_int32_t), intent(out) :: id
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: out_id
      out_id = -1
      call report(rkmpm_sim_add_material_drucker_prager(self%h, density, young, poisson, &
                  friction_angle, cohesion, dilatancy_angle, out_id), &
                  'add_material_drucker_prager', stat, text)
      if (present(errmsg)) errmsg = text
      id = out_id
   end subroutine sim_add_material_drucker_prager

   !> Adds a Johnson-Cook metal; see type(rkmpm_johnson_cook) and the C header.
   subroutine sim_add_material_johnson_cook(self, parameters, id, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      type(rkmpm_johnson_cook), intent(in) :: parameters
      integer(c_int32_t), intent(out) :: id
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: out_id
      out_id = -1
      call report(rkmpm_sim_add_material_johnson_cook(self%h, parameters, out_id), &
                  'add_material_johnson_cook', stat, text)
      if (present(errmsg)) errmsg = text
      id = out_id
   end subroutine sim_add_material_johnson_cook

   !> Adds a rigid body moving with velocity(dim); needs set_contact.
   subroutine sim_add_material_rigid(self, density, velocity, id, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: density
      real(c_double), intent(in) :: velocity(:)
      integer(c_int32_t), intent(out) :: id
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: out_id
      out_id = -1
      if (c_associated(self%h)) then
         if (size(velocity) /= handle_dim(self%h)) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'add_material_rigid', stat, text, &
                        'velocity must hold dim values')
            if (present(errmsg)) errmsg = text
            id = out_id
            return
         end if
      end if
      call report(rkmpm_sim_add_material_rigid(self%h, density, velocity, out_id), &
                  'add_material_rigid', stat, text)
      if (present(errmsg)) errmsg = text
      id = out_id
   end subroutine sim_add_material_rigid

   !> Changes the prescribed velocity(dim) of the rigid `material` for the steps that follow.
   subroutine sim_set_rigid_velocity(self, material, velocity, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: material
      real(c_double), intent(in) :: velocity(:)
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      if (c_associated(self%h)) then
         if (size(velocity) /= handle_dim(self%h)) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'set_rigid_velocity', stat, text, &
                        'velocity must hold dim values')
            if (present(errmsg)) errmsg = text
            return
         end if
      end if
      call report(rkmpm_sim_set_rigid_velocity(self%h, material, velocity), &
                  'set_rigid_velocity', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_rigid_velocity

   !> Turns contact between bodies on (enabled = .true., Coulomb friction) or off.
   subroutine sim_set_contact(self, enabled, friction, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      logical, intent(in) :: enabled
      real(c_double), intent(in) :: friction
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: on
      on = 0
      if (enabled) on = 1
      call report(rkmpm_sim_set_contact(self%h, on, friction), 'set_contact', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_contact

   !> Gives the Drucker-Prager `material` the mu(I) rate dependence of its friction
   !> (enabled = .true.: friction_increase >= 0, reference_inertial_number > 0, grain_diameter > 0
   !> in m) or takes it away; may change between steps. See the C header.
   subroutine sim_set_drucker_prager_rheology(self, material, enabled, friction_increase, &
                                              reference_inertial_number, grain_diameter, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: material
      logical, intent(in) :: enabled
      real(c_double), intent(in) :: friction_increase, reference_inertial_number, grain_diameter
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: on
      on = 0
      if (enabled) on = 1
      call report(rkmpm_sim_set_drucker_prager_rheology(self%h, material, on, friction_increase, &
                                                        reference_inertial_number, grain_diameter), &
                  'set_drucker_prager_rheology', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_drucker_prager_rheology

   !> Adds size(x, 2) particles of `material`: positions x(dim, n), volumes(n) and optional
   !> velocities(dim, n) (at rest when absent). All or nothing.
   subroutine sim_add_particles(self, material, x, volumes, velocities, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: material
      real(c_double), contiguous, intent(in) :: x(:, :)
      real(c_double), contiguous, intent(in) :: volumes(:)
      real(c_double), contiguous, intent(in), optional :: velocities(:, :)
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: d
      integer(c_int) :: status
      if (c_associated(self%h)) then
         d = handle_dim(self%h)
         if (size(x, 1) /= d) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'add_particles', stat, text, &
                        'size(x, 1) must equal the dimension')
            if (present(errmsg)) errmsg = text
            return
         end if
         if (size(volumes) /= size(x, 2)) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'add_particles', stat, text, &
                        'size(volumes) must equal size(x, 2), the number of particles')
            if (present(errmsg)) errmsg = text
            return
         end if
         if (present(velocities)) then
            if (any(shape(velocities) /= shape(x))) then
               call report(RKMPM_ERR_INVALID_ARGUMENT, 'add_particles', stat, text, &
                           'velocities must have the shape of x')
               if (present(errmsg)) errmsg = text
               return
            end if
         end if
      end if
      if (present(velocities)) then
         status = rkmpm_sim_add_particles(self%h, material, int(size(x, 2), c_size_t), x, volumes, velocities)
      else
         status = rkmpm_sim_add_particles(self%h, material, int(size(x, 2), c_size_t), x, volumes)
      end if
      call report(status, 'add_particles', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_add_particles

   !> Adds size(x, 2) boundary points on the material's surface: positions x(dim, n), outward
   !> normals times area area_normals(dim, n) (length in 2D; non-zero) and optional tractions(dim, n)
   !> (force per current area). They close VC integration's divergence equality and carry the
   !> tractions. All or nothing.
   subroutine sim_add_boundary_points(self, x, area_normals, tractions, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), contiguous, intent(in) :: x(:, :)
      real(c_double), contiguous, intent(in) :: area_normals(:, :)
      real(c_double), contiguous, intent(in), optional :: tractions(:, :)
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int) :: status
      if (c_associated(self%h)) then
         if (size(x, 1) /= handle_dim(self%h)) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'add_boundary_points', stat, text, &
                        'size(x, 1) must equal the dimension')
            if (present(errmsg)) errmsg = text
            return
         end if
         if (any(shape(area_normals) /= shape(x))) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'add_boundary_points', stat, text, &
                        'area_normals must have the shape of x')
            if (present(errmsg)) errmsg = text
            return
         end if
         if (present(tractions)) then
            if (any(shape(tractions) /= shape(x))) then
               call report(RKMPM_ERR_INVALID_ARGUMENT, 'add_boundary_points', stat, text, &
                           'tractions must have the shape of x')
               if (present(errmsg)) errmsg = text
               return
            end if
         end if
      end if
      if (present(tractions)) then
         status = rkmpm_sim_add_boundary_points(self%h, int(size(x, 2), c_size_t), x, area_normals, tractions)
      else
         status = rkmpm_sim_add_boundary_points(self%h, int(size(x, 2), c_size_t), x, area_normals)
      end if
      call report(status, 'add_boundary_points', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_add_boundary_points

   !> The number of boundary points VC integrated over in the last step (given, or found on the
   !> surface of the particles).
   integer(c_size_t) function sim_boundary_point_count(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_size_t) :: n
      n = 0
      call report(rkmpm_sim_boundary_point_count(self%h, n), 'boundary_point_count', stat, text)
      if (present(errmsg)) errmsg = text
      sim_boundary_point_count = n
   end function sim_boundary_point_count

   !> cfl * h / max_p(c_p + |v_p|), with cfl in (0, 1].
   real(c_double) function sim_stable_dt(self, cfl, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      real(c_double), intent(in) :: cfl
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      real(c_double) :: dt
      dt = 0
      call report(rkmpm_sim_stable_dt(self%h, cfl, dt), 'stable_dt', stat, text)
      if (present(errmsg)) errmsg = text
      sim_stable_dt = dt
   end function sim_stable_dt

   !> Advances by dt; on failure the simulation keeps its last good state.
   subroutine sim_step(self, dt, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: dt
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_step(self%h, dt), 'step', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_step

   !> Advances by `duration` with adaptive steps of `cfl` (in (0, 1]) times the stable step,
   !> recomputed before every step, ending exactly at time + duration. `steps` (optional) gets
   !> the number of steps taken, also on failure; on failure the simulation keeps the state after
   !> the last good step.
   subroutine sim_advance(self, duration, cfl, steps, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: duration, cfl
      integer(c_int64_t), intent(out), optional :: steps
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int64_t) :: n
      n = 0
      call report(rkmpm_sim_advance(self%h, duration, cfl, n), 'advance', stat, text)
      if (present(steps)) steps = n
      if (present(errmsg)) errmsg = text
   end subroutine sim_advance

   !> Bounds the steps one advance may take (default RKMPM_DEFAULT_MAX_STEPS_PER_ADVANCE, 10^9):
   !> a run whose estimate duration / stable step exceeds it is refused before its first step
   !> with RKMPM_ERR_INVALID_ARGUMENT and the estimate in the message; a run whose stable step
   !> shrinks on the way stops there once it has taken max_steps steps (they stay taken).
   !> max_steps < 1 is refused; huge(0_c_int64_t) sets no practical bound. To stop a run
   !> earlier by its own measure, a host returns non-zero from the progress callback
   !> (set_progress). Not part of a checkpoint.
   subroutine sim_set_max_steps_per_advance(self, max_steps, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int64_t), intent(in) :: max_steps
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      ! C takes an unsigned count: a negative one is passed as 0, which C refuses.
      call report(rkmpm_sim_set_max_steps_per_advance(self%h, max(max_steps, 0_c_int64_t)), &
         'set_max_steps_per_advance', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_max_steps_per_advance

   !> The bound on the steps of one advance.
   integer(c_int64_t) function sim_max_steps_per_advance(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int64_t) :: n
      n = 0
      call report(rkmpm_sim_max_steps_per_advance(self%h, n), 'max_steps_per_advance', stat, text)
      if (present(errmsg)) errmsg = text
      sim_max_steps_per_advance = n
   end function sim_max_steps_per_advance

   !> The stopping rule of VC's solve: tolerance in (0, 1] of the right-hand side's residual
   !> (default 1e-4 at order 1; 1e-12 is the exact solve), at most max_iterations (>= 1) iterations.
   subroutine sim_set_vc_solve(self, tolerance, max_iterations, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      real(c_double), intent(in) :: tolerance
      integer(c_int64_t), intent(in) :: max_iterations
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      ! C takes an unsigned count: a negative one is passed as 0, which C refuses.
      call report(rkmpm_sim_set_vc_solve(self%h, tolerance, max(max_iterations, 0_c_int64_t)), &
         'set_vc_solve', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_vc_solve

   !> The stopping rule of VC's solve (sim%set_vc_solve).
   subroutine sim_vc_solve(self, tolerance, max_iterations, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      real(c_double), intent(out) :: tolerance
      integer(c_int64_t), intent(out) :: max_iterations
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      tolerance = 0
      max_iterations = 0
      call report(rkmpm_sim_vc_solve(self%h, tolerance, max_iterations), 'vc_solve', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_vc_solve

   !> Every how many steps VC's solve runs (default every step, at order 1
   !> RKMPM_BSPLINE_VC_SOLVE_INTERVAL, 2, with B-splines and RKMPM_RK_VC_SOLVE_INTERVAL, 4, with
   !> RK shape functions to RKMPM_BSPLINE_VC_CARRIED_CELLS and RKMPM_RK_VC_CARRIED_CELLS cells
   !> across, halved with every doubling beyond; order >= 2 and contact solve at every step):
   !> the steps between take
   !> the last solve's coefficients, carried by grid node along the line through the last two
   !> solves. Momentum is conserved
   !> whatever the interval.
   !> Keeps the tolerance and iteration bound in force. steps < 1 is refused. Part of a
   !> checkpoint.
   subroutine sim_set_vc_solve_interval(self, steps, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: steps
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      ! C takes an unsigned count: a negative one is passed as 0, which C refuses.
      call report(rkmpm_sim_set_vc_solve_interval(self%h, max(steps, 0_c_int32_t)), &
         'set_vc_solve_interval', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_vc_solve_interval

   !> Every how many steps VC's solve runs (sim%set_vc_solve_interval).
   integer(c_int32_t) function sim_vc_solve_interval(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: n
      n = 0
      call report(rkmpm_sim_vc_solve_interval(self%h, n), 'vc_solve_interval', stat, text)
      if (present(errmsg)) errmsg = text
      sim_vc_solve_interval = n
   end function sim_vc_solve_interval

   !> Every how many steps VC finds the surface of the particles anew (VC without given
   !> boundary points, without contact; default RKMPM_DEFAULT_VC_SURFACE_REFRESH, 4): the grid
   !> carries the surface between like given boundary points; 1 finds it at every step.
   !> steps < 1 is refused. Part of a checkpoint.
   subroutine sim_set_vc_surface_refresh(self, steps, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: steps
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      ! C takes an unsigned count: a negative one is passed as 0, which C refuses.
      call report(rkmpm_sim_set_vc_surface_refresh(self%h, max(steps, 0_c_int32_t)), &
         'set_vc_surface_refresh', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_vc_surface_refresh

   !> Every how many steps VC finds the surface anew (sim%set_vc_surface_refresh).
   integer(c_int32_t) function sim_vc_surface_refresh(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: n
      n = 0
      call report(rkmpm_sim_vc_surface_refresh(self%h, n), 'vc_surface_refresh', stat, text)
      if (present(errmsg)) errmsg = text
      sim_vc_surface_refresh = n
   end function sim_vc_surface_refresh

   !> Gives the simulation its own `threads` worker threads (0: one per core), on which its
   !> steps run whatever other simulations or the host's threads (OpenMP's among them) do; until
   !> then it runs on the library's process-wide pool (RAYON_NUM_THREADS threads, or one per
   !> core). The same results to the last bit for any count. Refuses a negative count or more
   !> than RKMPM_MAX_THREADS. Not part of a checkpoint.
   subroutine sim_set_threads(self, threads, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: threads
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      if (threads < 0) then
         call report(RKMPM_ERR_INVALID_ARGUMENT, 'set_threads', stat, text, &
            'threads must not be negative (0 for one per core)')
      else
         call report(rkmpm_sim_set_threads(self%h, threads), 'set_threads', stat, text)
      end if
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_threads

   !> The number of worker threads the simulation's steps run on (sim%set_threads).
   integer(c_int32_t) function sim_threads(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int32_t) :: n
      n = 0
      call report(rkmpm_sim_threads(self%h, n), 'threads', stat, text)
      if (present(errmsg)) errmsg = text
      sim_threads = n
   end function sim_threads

   !> The energies of the particles now.
   type(rkmpm_energies) function sim_energies(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      type(rkmpm_energies) :: e
      call report(rkmpm_sim_energies(self%h, e), 'energies', stat, text)
      if (present(errmsg)) errmsg = text
      sim_energies = e
   end function sim_energies

   !> Switches the energy accounting on (from the energies now) or off.
   subroutine sim_set_energy_accounting(self, on, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      logical, intent(in) :: on
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_set_energy_accounting(self%h, merge(1_c_int32_t, 0_c_int32_t, on)), &
         'set_energy_accounting', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_energy_accounting

   !> Where the energy went since the accounting started (fails while it is off).
   type(rkmpm_energy_balance) function sim_energy_balance(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      type(rkmpm_energy_balance) :: b
      call report(rkmpm_sim_energy_balance(self%h, b), 'energy_balance', stat, text)
      if (present(errmsg)) errmsg = text
      sim_energy_balance = b
   end function sim_energy_balance

   !> The particles' linear and angular momentum now.
   type(rkmpm_momenta) function sim_momenta(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      type(rkmpm_momenta) :: p
      call report(rkmpm_sim_momenta(self%h, p), 'momenta', stat, text)
      if (present(errmsg)) errmsg = text
      sim_momenta = p
   end function sim_momenta

   !> The simulated time.
   real(c_double) function sim_time(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      real(c_double) :: t
      t = 0
      call report(rkmpm_sim_time(self%h, t), 'time', stat, text)
      if (present(errmsg)) errmsg = text
      sim_time = t
   end function sim_time

   !> The number of steps taken.
   integer(c_int64_t) function sim_step_count(self, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_int64_t) :: n
      n = 0
      call report(rkmpm_sim_step_count(self%h, n), 'step_count', stat, text)
      if (present(errmsg)) errmsg = text
      sim_step_count = n
   end function sim_step_count

   !> The number of particles (0 for an uninitialized object).
   integer(c_size_t) function sim_particle_count(self)
      class(rkmpm_sim), intent(in) :: self
      sim_particle_count = rkmpm_sim_particle_count(self%h)
   end function sim_particle_count

   !> How many values get_particles writes for `field` (particle count times values per particle).
   integer(c_size_t) function sim_field_len(self, field, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int32_t), intent(in) :: field
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_size_t) :: n
      n = 0
      call report(rkmpm_sim_field_len(self%h, field, n), 'field_len', stat, text)
      if (present(errmsg)) errmsg = text
      sim_field_len = n
   end function sim_field_len

   !> Copies `field` of every particle into out(:) (particle-major, see the RKMPM_FIELD_*
   !> comments); size(out) must be at least field_len(field) (else RKMPM_ERR_BUFFER_TOO_SMALL
   !> and nothing is written).
   subroutine sim_get_particles_1d(self, field, out, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int32_t), intent(in) :: field
      real(c_double), contiguous, intent(inout) :: out(:)
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_get_particles(self%h, field, out, int(size(out), c_size_t)), &
                  'get_particles', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_get_particles_1d

   !> Copies `field` into out(k, p) = value k of particle p: size(out, 1) must be the number of
   !> values per particle (dim, dim*dim or 1) and size(out, 2) at least the particle count.
   subroutine sim_get_particles_2d(self, field, out, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      integer(c_int32_t), intent(in) :: field
      real(c_double), contiguous, intent(inout) :: out(:, :)
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      integer(c_size_t) :: n, count
      integer(c_int) :: status
      status = rkmpm_sim_field_len(self%h, field, n)
      if (status /= RKMPM_OK) then
         call report(status, 'get_particles', stat, text)
         if (present(errmsg)) errmsg = text
         return
      end if
      count = rkmpm_sim_particle_count(self%h)
      if (count > 0) then
         if (int(size(out, 1), c_size_t) /= n / count) then
            call report(RKMPM_ERR_INVALID_ARGUMENT, 'get_particles', stat, text, &
                        'size(out, 1) must equal the number of values per particle of the field')
            if (present(errmsg)) errmsg = text
            return
         end if
      end if
      call report(rkmpm_sim_get_particles(self%h, field, out, int(size(out), c_size_t)), &
                  'get_particles', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_get_particles_2d

   !> How the VTK files written from now on store their arrays: RKMPM_VTK_BINARY (the default)
   !> or RKMPM_VTK_ASCII.
   subroutine sim_set_vtk_format(self, format, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      integer(c_int32_t), intent(in) :: format
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_set_vtk_format(self%h, format), 'set_vtk_format', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_set_vtk_format

   !> Writes the particles to one VTK .vtu file at trim(path).
   subroutine sim_write_vtk(self, path, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      character(*), intent(in) :: path
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_write_vtk(self%h, trim(path)//c_null_char), 'write_vtk', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_write_vtk

   !> Saves a checkpoint of the whole simulation to trim(path) (atomically; see the C header).
   subroutine sim_save(self, path, stat, errmsg)
      class(rkmpm_sim), intent(in) :: self
      character(*), intent(in) :: path
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_save(self%h, trim(path)//c_null_char), 'save', stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_save

   !> Loads a checkpoint from trim(path) into this (uninitialized) object; continuing it gives
   !> the saved run's particle data bit for bit. The body force must be set again.
   subroutine sim_load(self, path, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      character(*), intent(in) :: path
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      type(c_ptr) :: h
      if (c_associated(self%h)) then
         call report(RKMPM_ERR_INVALID_STATE, 'load', stat, text, &
                     'this rkmpm_sim already holds a simulation; call free first')
         if (present(errmsg)) errmsg = text
         return
      end if
      call report(rkmpm_sim_load(trim(path)//c_null_char, h), 'load', stat, text)
      if (present(errmsg)) errmsg = text
      self%h = h
   end subroutine sim_load

   !> Writes the next frame <prefix>_NNNNN.vtu of a time series and rewrites <prefix>.pvd
   !> (prefix = trim(prefix)).
   subroutine sim_write_vtk_frame(self, prefix, stat, errmsg)
      class(rkmpm_sim), intent(inout) :: self
      character(*), intent(in) :: prefix
      integer(c_int), intent(out), optional :: stat
      character(:), allocatable, intent(out), optional :: errmsg
      character(:), allocatable :: text
      call report(rkmpm_sim_write_vtk_frame(self%h, trim(prefix)//c_null_char), 'write_vtk_frame', &
                  stat, text)
      if (present(errmsg)) errmsg = text
   end subroutine sim_write_vtk_frame

end module rkmpm
