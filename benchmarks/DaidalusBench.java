// Times NASA DAIDALUS (Java) on the conformance encounters for benchmarks/bench_daidalus.py (our code;
// no DAIDALUS code here: it is compiled against the DAIDALUS jar the user gives).
//
//   java -cp DAIDALUSv2.0.4.jar:. DaidalusBench CONF|- INPUT SECONDS
//
// CONF: a DAIDALUS configuration file (DO_365B_no_SUM.conf), or "-" for set_DO_365B(true, false).
// INPUT: one encounter a line, 12 numbers: ownship x y z (m, ENU) vx vy vz (m/s), intruder the same.
// Each evaluation computes what daa-sil's DAIDALUS comparison reads: the alert level; the track,
// ground-speed and vertical-speed bands with their regions; the region of each current value; the
// resolutions on both sides; the preferred directions; the recovery information of each axis.
// Prints "evaluations N seconds S checksum C" for the timed passes (the thread's CPU time), the
// per-encounter CPU times in INPUT order ("times", ns, the median of the rounds), and each encounter's alert level and number of track
// bands ("levels", level:bands) for the caller to check against the reference.

import gov.nasa.larcfm.ACCoRD.BandsRegion;
import gov.nasa.larcfm.ACCoRD.Daidalus;
import gov.nasa.larcfm.ACCoRD.RecoveryInformation;
import gov.nasa.larcfm.ACCoRD.TrafficState;
import gov.nasa.larcfm.Util.Interval;
import gov.nasa.larcfm.Util.Position;
import gov.nasa.larcfm.Util.Velocity;

import java.io.BufferedReader;
import java.io.FileReader;
import java.lang.management.ManagementFactory;
import java.lang.management.ThreadMXBean;
import java.util.ArrayList;
import java.util.Arrays;
import java.util.List;

public class DaidalusBench {
    static long mix(long acc, double x) {
        return acc * 1099511628211L + Double.doubleToLongBits(x);
    }

    static long region(long acc, BandsRegion r) {
        return acc * 31 + r.ordinal();
    }

    static long recovery(long acc, RecoveryInformation ri) {
        acc = mix(acc, ri.timeToRecovery());
        acc = acc * 31 + ri.nFactor();
        acc = mix(acc, ri.recoveryHorizontalDistance());
        return mix(acc, ri.recoveryVerticalDistance());
    }

    /** One encounter: the outputs, folded into a checksum (so that nothing is skipped). */
    static long evaluate(Daidalus daa, double[] r) {
        daa.setOwnshipState("own", Position.makeXYZ(r[0], "m", r[1], "m", r[2], "m"),
                Velocity.makeVxyz(r[3], r[4], "m/s", r[5], "m/s"), 0.0);
        daa.addTrafficState("int", Position.makeXYZ(r[6], "m", r[7], "m", r[8], "m"),
                Velocity.makeVxyz(r[9], r[10], "m/s", r[11], "m/s"));
        long acc = daa.alertLevel(1);
        TrafficState own = daa.getOwnshipState();
        for (int i = 0; i < daa.horizontalDirectionBandsLength(); i++) {
            Interval iv = daa.horizontalDirectionIntervalAt(i);
            acc = region(mix(mix(acc, iv.low), iv.up), daa.horizontalDirectionRegionAt(i));
        }
        acc = region(acc, daa.regionOfHorizontalDirection(own.horizontalDirection()));
        acc = mix(mix(acc, daa.horizontalDirectionResolution(true)), daa.horizontalDirectionResolution(false));
        acc = acc * 31 + (daa.preferredHorizontalDirectionRightOrLeft() ? 1 : 0);
        acc = recovery(acc, daa.horizontalDirectionRecoveryInformation());
        for (int i = 0; i < daa.horizontalSpeedBandsLength(); i++) {
            Interval iv = daa.horizontalSpeedIntervalAt(i);
            acc = region(mix(mix(acc, iv.low), iv.up), daa.horizontalSpeedRegionAt(i));
        }
        acc = region(acc, daa.regionOfHorizontalSpeed(own.horizontalSpeed()));
        acc = mix(mix(acc, daa.horizontalSpeedResolution(true)), daa.horizontalSpeedResolution(false));
        acc = acc * 31 + (daa.preferredHorizontalSpeedUpOrDown() ? 1 : 0);
        acc = recovery(acc, daa.horizontalSpeedRecoveryInformation());
        for (int i = 0; i < daa.verticalSpeedBandsLength(); i++) {
            Interval iv = daa.verticalSpeedIntervalAt(i);
            acc = region(mix(mix(acc, iv.low), iv.up), daa.verticalSpeedRegionAt(i));
        }
        acc = region(acc, daa.regionOfVerticalSpeed(own.verticalSpeed()));
        acc = mix(mix(acc, daa.verticalSpeedResolution(true)), daa.verticalSpeedResolution(false));
        acc = acc * 31 + (daa.preferredVerticalSpeedUpOrDown() ? 1 : 0);
        return recovery(acc, daa.verticalSpeedRecoveryInformation());
    }

    public static void main(String[] args) throws Exception {
        if (args.length != 3) {
            System.err.println("usage: DaidalusBench CONF|- INPUT SECONDS");
            System.exit(2);
        }
        Daidalus daa = new Daidalus();
        if (args[0].equals("-")) {
            daa.set_DO_365B(true, false);
        } else if (!daa.loadFromFile(args[0])) {
            System.err.println("DaidalusBench: cannot read the configuration " + args[0]);
            System.exit(2);
        }
        List<double[]> recs = new ArrayList<>();
        try (BufferedReader in = new BufferedReader(new FileReader(args[1]))) {
            String line;
            while ((line = in.readLine()) != null) {
                String[] f = line.trim().split("\\s+");
                double[] r = new double[12];
                for (int k = 0; k < 12; k++) {
                    r[k] = Double.parseDouble(f[k]);
                }
                recs.add(r);
            }
        }
        double seconds = Double.parseDouble(args[2]);
        int n = recs.size();
        long sink = 0;
        // warm-up (the JIT compiles the hot paths): a third of the time
        long end = System.nanoTime() + (long) (seconds / 3 * 1e9);
        int warm = 0;
        while (System.nanoTime() < end || warm < 2) {
            for (double[] r : recs) {
                sink ^= evaluate(daa, r);
            }
            warm++;
        }
        // timed: whole passes over the encounters, each encounter timed alone too, in this thread's CPU time
        // (the machine may be shared: wall time would count the other processes' turns)
        ThreadMXBean cpu = ManagementFactory.getThreadMXBean();
        List<long[]> rounds = new ArrayList<>();
        long evals = 0;
        long c0 = cpu.getCurrentThreadCpuTime();
        end = System.nanoTime() + (long) (seconds * 1e9);
        while (System.nanoTime() < end || rounds.size() < 3) {
            long[] times = new long[n];
            for (int i = 0; i < n; i++) {
                long a = cpu.getCurrentThreadCpuTime();
                sink ^= evaluate(daa, recs.get(i));
                times[i] = cpu.getCurrentThreadCpuTime() - a;
            }
            rounds.add(times);
            evals += n;
        }
        double dt = (cpu.getCurrentThreadCpuTime() - c0) / 1e9;
        System.out.println("evaluations " + evals + " seconds " + dt + " checksum " + sink);
        StringBuilder sb = new StringBuilder("times");
        for (int i = 0; i < n; i++) {
            long[] col = new long[rounds.size()];
            for (int k = 0; k < col.length; k++) {
                col[k] = rounds.get(k)[i];
            }
            Arrays.sort(col);
            sb.append(' ').append(col[col.length / 2]);
        }
        System.out.println(sb);
        // the alert level and the number of track bands of each encounter (checked against the reference)
        StringBuilder lv = new StringBuilder("levels");
        for (double[] r : recs) {
            evaluate(daa, r);
            lv.append(' ').append(daa.alertLevel(1)).append(':').append(daa.horizontalDirectionBandsLength());
        }
        System.out.println(lv);
    }
}
