/* Kernel wake-up baseline for benchmarks/controller_manager_bench.py: the controller manager's
   wait, without Python. A SCHED_FIFO thread on one CPU sleeps (clock_nanosleep, absolute) until
   `spin_us` before each deadline, then busy-waits to the deadline, with the manager loop's
   schedule (deadline += period, never sooner than 0.98 period after the last start). What it
   measures late is the kernel's and the machine's doing (wake-up latency, a CPU taken away),
   not the interpreter's.

   Also the benchmarks' witness of the machine: run beside a manager at a higher priority with
   no spin, it says when the CPU itself was late (SIGINT or SIGTERM ends the run early, and
   the cycles so far are written).

   usage: wakeup_baseline PRIORITY PERIOD_US SECONDS CPU SPIN_US OUT_FILE
   OUT_FILE: three float64 arrays of n cycles (deadline, start, woke), CLOCK_MONOTONIC s,
   one after the other; woke = when the sleep returned. Exit 2 when SCHED_FIFO is refused. */
#define _GNU_SOURCE
#include <sched.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static double now_s(void) {
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return t.tv_sec + t.tv_nsec * 1e-9;
}

static struct timespec to_timespec(double s) {
  struct timespec t = {(time_t)s, (long)((s - (double)(time_t)s) * 1e9)};
  return t;
}

static volatile sig_atomic_t stopping = 0;

static void on_stop(int signal_number) {
  (void)signal_number;
  stopping = 1;
}

int main(int argc, char **argv) {
  if (argc != 7) {
    fprintf(stderr, "usage: %s PRIORITY PERIOD_US SECONDS CPU SPIN_US OUT_FILE\n", argv[0]);
    return 1;
  }
  int priority = atoi(argv[1]), cpu = atoi(argv[4]);
  double period = atof(argv[2]) * 1e-6, seconds = atof(argv[3]), spin = atof(argv[5]) * 1e-6;
  cpu_set_t set;
  CPU_ZERO(&set);
  CPU_SET(cpu, &set);
  if (sched_setaffinity(0, sizeof set, &set) != 0) { perror("sched_setaffinity"); return 1; }
  struct sched_param param = {.sched_priority = priority};
  if (sched_setscheduler(0, SCHED_FIFO, &param) != 0) { perror("sched_setscheduler"); return 2; }
  struct sigaction stop = {.sa_handler = on_stop};  /* no SA_RESTART: the sleep returns EINTR */
  sigaction(SIGINT, &stop, NULL);
  sigaction(SIGTERM, &stop, NULL);
  long n = (long)(seconds / period);
  double *log = calloc(3 * (size_t)n, sizeof *log);
  if (log == NULL) return 1;
  double *deadline = log, *start = log + n, *woke = log + 2 * n;
  double next = now_s(), previous_start = 0.0;
  long done = 0;
  for (long i = 0; i < n && !stopping; i++) {
    next += period;
    if (i > 0 && next < previous_start + 0.98 * period) next = previous_start + 0.98 * period;
    struct timespec wake_at = to_timespec(next - spin);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &wake_at, NULL) != 0 && !stopping) {}
    if (stopping) break;
    woke[i] = now_s();
    double t;
    do t = now_s(); while (t < next);
    deadline[i] = next;
    start[i] = previous_start = t;
    done = i + 1;
  }
  FILE *out = fopen(argv[6], "wb");
  if (out == NULL) { perror("open"); return 1; }
  for (int k = 0; k < 3; k++)  /* the cycles done of each array, one array after the other */
    if (fwrite(log + k * n, sizeof *log, (size_t)done, out) != (size_t)done) { perror("write"); return 1; }
  fclose(out);
  return 0;
}
